//! IO bridge: every cycle it writes the robot position into the fieldbus output image with
//! the time of the measurement it came from, as the CS9 synchronous task of seed 000 §5 does
//! (`aioSet(aOutTimeStamp, ...)`, `aioSet(aOutPoint[i], ...)`). The position is the one servo
//! used in its latest cycle, so the image is one servo cycle (plus the phase between the two
//! processes) behind the encoders, and the timestamp makes that delay visible to whoever reads
//! the image. The fieldbus is simulated in this version: the image is published on
//! `<i>/iobridge/output`.
//!
//! iobridge also owns the cell's named digital IO ([`digital`]): it takes the field's inputs
//! and the output requests, sets the outputs to their safe values when it reacts to an e-stop,
//! raises the e-stop when an e-stop input opens, and publishes the IO image every cycle.

pub mod digital;

use shm_schema::drive::{FIELDBUS_IMAGE_LEN, milli_units};
use shm_schema::{FieldbusImageV1, ServoStateV3};

/// Bytes of the timestamp at the start of the image.
pub const STAMP_BYTES: usize = 8;
/// Axes that fit in the image.
pub const IMAGE_AXES: usize = (FIELDBUS_IMAGE_LEN - STAMP_BYTES) / 4;

/// Writes the output image for `state`, stamped `written_ns`: the time it is written, read after
/// `state` (never before `state.measured_stamp_ns`).
///
/// # Real-time
/// Arithmetic and byte copies only.
pub fn write_image(seq: u64, written_ns: u64, state: &ServoStateV3) -> FieldbusImageV1 {
    let axes = (state.axes as usize).min(IMAGE_AXES);
    let mut image = [0u8; FIELDBUS_IMAGE_LEN];
    image[..STAMP_BYTES].copy_from_slice(&(state.measured_stamp_ns / 1000).to_le_bytes());
    for i in 0..axes {
        let at = STAMP_BYTES + 4 * i;
        image[at..at + 4].copy_from_slice(&milli_units(state.act_position[i]).to_le_bytes());
    }
    FieldbusImageV1 {
        seq,
        written_ns,
        measured_ns: state.measured_stamp_ns,
        source_seq: state.seq,
        len: (STAMP_BYTES + 4 * axes) as u32,
        axes: axes as u32,
        image,
    }
}

/// Decodes an image: (measurement time µs, positions in axis units; NaN for
/// [`shm_schema::drive::IMAGE_INVALID`]).
pub fn read_image(img: &FieldbusImageV1) -> (u64, [f64; IMAGE_AXES]) {
    let mut stamp = [0u8; 8];
    stamp.copy_from_slice(&img.image[..STAMP_BYTES]);
    let mut pos = [0.0; IMAGE_AXES];
    for (i, p) in pos
        .iter_mut()
        .enumerate()
        .take((img.axes as usize).min(IMAGE_AXES))
    {
        *p = img.position(i).unwrap_or(f64::NAN);
    }
    (u64::from_le_bytes(stamp), pos)
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schema::drive::IMAGE_INVALID;

    #[test]
    fn the_image_carries_the_measurement_time_and_positions() {
        let mut s = ServoStateV3 {
            seq: 9,
            measured_stamp_ns: 123_456_789_000,
            axes: 3,
            ..Default::default()
        };
        s.act_position[..3].copy_from_slice(&[40.0015, -0.002, 179.999]);
        let img = write_image(1, 123_460_000_000, &s);
        assert_eq!(img.len, 20);
        assert_eq!(&img.image[..8], &123_456_789u64.to_le_bytes());
        let (stamp, pos) = read_image(&img);
        assert_eq!(stamp, 123_456_789);
        assert_eq!(&pos[..3], &[40.002, -0.002, 179.999]);
        assert_eq!(img.written_ns - img.measured_ns, 3_211_000);
    }

    #[test]
    fn a_position_that_is_not_finite_is_marked_invalid_not_zero() {
        let mut s = ServoStateV3 {
            axes: 2,
            ..Default::default()
        };
        s.act_position[..2].copy_from_slice(&[f64::NAN, f64::INFINITY]);
        let img = write_image(1, 0, &s);
        assert_eq!(&img.image[8..12], &IMAGE_INVALID.to_le_bytes());
        let (_, pos) = read_image(&img);
        assert!(pos[0].is_nan() && pos[1].is_nan());
        assert_eq!(milli_units(-1e300), IMAGE_INVALID + 1);
    }
}
