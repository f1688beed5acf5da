//! The cell's joint states as ROS 2 sees them through `rmw_zenoh` (Jazzy, rmw_zenoh 0.2.4 and
//! later; docs/network.md says what was checked and how): a `sensor_msgs/msg/JointState` on
//! the key `<domain>/<namespace>/joint_states/<type>/<type hash>`, its payload CDR
//! little-endian with its encapsulation header, its attachment the sequence number, the
//! source time stamp and the publisher's GID; and the node and its publishers in ROS 2's graph
//! (liveliness tokens `@ros2_lv/...`), so that `ros2 topic list` and `ros2 topic echo` find
//! them.

/// The type's name as rmw_zenoh writes it in a key.
pub const JOINT_STATE_TYPE: &str = "sensor_msgs::msg::dds_::JointState_";
/// The type's hash (REP 2016, RIHS01): PyPI `rosbags` 0.11.9's `hash_rihs01` of
/// `sensor_msgs/msg/JointState` on Jazzy, which the tests check again.
pub const JOINT_STATE_HASH: &str =
    "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e";
/// The topic under the cell's namespace.
pub const JOINT_STATES: &str = "joint_states";
/// The tool pose's type as rmw_zenoh writes it in a key.
pub const POSE_STAMPED_TYPE: &str = "geometry_msgs::msg::dds_::PoseStamped_";
/// `geometry_msgs/msg/PoseStamped`'s hash on Jazzy (rosbags 0.11.9, as above).
pub const POSE_STAMPED_HASH: &str =
    "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8";
/// The tool pose's topic under the cell's namespace.
pub const TOOL_POSE: &str = "tool_pose";

/// The ROS node that publishes a cell's topics, in the cell's namespace.
pub const NODE: &str = "rtc_gateway";

/// The QoS every publisher declares in its token: reliable, volatile, keep last 10 (rmw_zenoh
/// writes a default as an empty field: `<reliability>:<durability>:<history>,<depth>:
/// <deadline>:<lifespan>:<liveliness>`).
pub const QOS: &str = "::,10:,:,:,,";

/// A ROS name as rmw_zenoh writes it in a graph token: each `/` as `%` (`/press_0/joint_states`
/// is `%press_0%joint_states`).
pub fn mangle(name: &str) -> String {
    name.replace('/', "%")
}

/// The node's liveliness token in ROS 2's graph (rmw_zenoh's design document, Jazzy):
/// `@ros2_lv/<domain>/<session id>/<node id>/<node id>/NN/<enclave>/<namespace>/<node>`.
pub fn node_token(domain: u32, zid: &str, namespace: &str) -> String {
    format!(
        "@ros2_lv/{domain}/{zid}/0/0/NN/%/{}/{NODE}",
        mangle(&format!("/{namespace}"))
    )
}

/// A publisher's liveliness token (entity `entity` of the node): `@ros2_lv/<domain>/<session
/// id>/<node id>/<entity id>/MP/<enclave>/<namespace>/<node>/<topic>/<type>/<hash>/<qos>`.
pub fn publisher_token(
    domain: u32,
    zid: &str,
    entity: u32,
    namespace: &str,
    topic: &str,
    type_name: &str,
    hash: &str,
) -> String {
    format!(
        "@ros2_lv/{domain}/{zid}/0/{entity}/MP/%/{}/{NODE}/{}/{type_name}/{hash}/{QOS}",
        mangle(&format!("/{namespace}")),
        mangle(&format!("/{namespace}/{topic}"))
    )
}

/// What of ROS 2's graph a cell may declare in domain `domain`: its own node's tokens, in its
/// namespace (the access control's key expression).
pub fn graph_keys(domain: u32, namespace: &str) -> String {
    format!(
        "@ros2_lv/{domain}/*/*/*/*/%/{}/**",
        mangle(&format!("/{namespace}"))
    )
}

/// The key of `/<namespace>/joint_states` in ROS domain `domain`.
pub fn joint_states_key(domain: u32, namespace: &str) -> String {
    format!("{domain}/{namespace}/{JOINT_STATES}/{JOINT_STATE_TYPE}/{JOINT_STATE_HASH}")
}

/// The key of `/<namespace>/tool_pose` in ROS domain `domain`.
pub fn tool_pose_key(domain: u32, namespace: &str) -> String {
    format!("{domain}/{namespace}/{TOOL_POSE}/{POSE_STAMPED_TYPE}/{POSE_STAMPED_HASH}")
}

/// A `geometry_msgs/msg/PoseStamped` in CDR: stamped `stamp_ns`, frame `frame_id`, at
/// `position` (m) turned by `yaw` (rad) about z (the quaternion `(0, 0, sin yaw/2, cos yaw/2)`).
pub fn pose_stamped(stamp_ns: u64, frame_id: &str, position: [f64; 3], yaw: f64) -> Vec<u8> {
    let mut w = Cdr::new();
    let (sec, nanosec) = stamp(stamp_ns);
    w.i32(sec);
    w.u32(nanosec);
    w.string(frame_id);
    for v in position {
        w.f64(v);
    }
    for v in [0.0, 0.0, (yaw / 2.0).sin(), (yaw / 2.0).cos()] {
        w.f64(v);
    }
    w.bytes
}

/// A ROS time stamp from nanoseconds since the Unix epoch.
pub fn stamp(ns: u64) -> (i32, u32) {
    let sec = i32::try_from(ns / 1_000_000_000).unwrap_or(i32::MAX);
    (sec, (ns % 1_000_000_000) as u32)
}

/// A `sensor_msgs/msg/JointState` in CDR (little-endian, with its encapsulation header):
/// stamped `stamp_ns` (since the Unix epoch), frame `frame_id`, each joint's name and position
/// (m or rad); velocity and effort empty (the message allows it: the cell's status has
/// neither).
pub fn joint_state(stamp_ns: u64, frame_id: &str, joints: &[(&str, f64)]) -> Vec<u8> {
    let mut w = Cdr::new();
    let (sec, nanosec) = stamp(stamp_ns);
    w.i32(sec);
    w.u32(nanosec);
    w.string(frame_id);
    w.u32(joints.len() as u32);
    for (name, _) in joints {
        w.string(name);
    }
    w.u32(joints.len() as u32);
    for (_, position) in joints {
        w.f64(*position);
    }
    w.u32(0); // velocity
    w.u32(0); // effort
    w.bytes
}

/// A publisher's GID as rmw_zenoh makes it (`liveliness::Entity`): the XXH3 128-bit hash of
/// its graph token's key, the low 64 bits then the high 64 bits, each little-endian. The same
/// in every attachment of the publisher and in what ROS 2 learns of it from the graph.
pub fn gid(token: &str) -> [u8; 16] {
    xxhash_rust::xxh3::xxh3_128(token.as_bytes()).to_le_bytes()
}

/// rmw_zenoh's attachment (since 0.2.4): the sequence number and the source time stamp (ns
/// since the Unix epoch), each an i64 little-endian, then the GID's length (16, one byte) and
/// the GID.
pub fn attachment(seq: i64, stamp_ns: i64, gid: &[u8; 16]) -> Vec<u8> {
    let mut a = Vec::with_capacity(33);
    a.extend_from_slice(&seq.to_le_bytes());
    a.extend_from_slice(&stamp_ns.to_le_bytes());
    a.push(16);
    a.extend_from_slice(gid);
    a
}

/// A CDR little-endian writer: each primitive aligned to its size from the end of the
/// encapsulation header.
struct Cdr {
    bytes: Vec<u8>,
}

impl Cdr {
    /// The encapsulation header: CDR_LE, no options.
    const HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

    fn new() -> Self {
        Self {
            bytes: Self::HEADER.to_vec(),
        }
    }

    fn align(&mut self, n: usize) {
        while !(self.bytes.len() - Self::HEADER.len()).is_multiple_of(n) {
            self.bytes.push(0);
        }
    }

    fn u32(&mut self, v: u32) {
        self.align(4);
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }

    fn i32(&mut self, v: i32) {
        self.align(4);
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }

    fn f64(&mut self, v: f64) {
        self.align(8);
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }

    /// Its length with the terminating NUL, its bytes, the NUL.
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.bytes.extend_from_slice(s.as_bytes());
        self.bytes.push(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bytes PyPI `rosbags` 0.11.9 serialises for the same message (`serialize_cdr`,
    /// Jazzy's type store); the integration test checks live messages against it too.
    #[test]
    fn a_joint_state_is_the_bytes_rosbags_writes() {
        let ours = joint_state(
            5_000_000_007,
            "press_0",
            &[("x", 0.04), ("y", 0.04), ("theta", 0.0)],
        );
        let rosbags = "0001000005000000070000000800000070726573735f300003000000020000007800\
                       00000200000079000000060000007468657461000000030000007b14ae47e17aa43f\
                       7b14ae47e17aa43f00000000000000000000000000000000";
        let hex: String = ours.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(hex, rosbags);
    }

    /// The same for a tool pose 30 degrees about z.
    #[test]
    fn a_pose_stamped_is_the_bytes_rosbags_writes() {
        let ours = pose_stamped(
            5_000_000_007,
            "press_0",
            [0.04, 0.05, 0.0],
            30f64.to_radians(),
        );
        let rosbags = "0001000005000000070000000800000070726573735f3000000000007b14ae47e17a\
                       a43f9a9999999999a93f000000000000000000000000000000000000000000000000\
                       900693c17d90d03f15bf4847dde8ee3f";
        let hex: String = ours.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(hex, rosbags);
        assert!(tool_pose_key(0, "p").ends_with(POSE_STAMPED_HASH));
    }

    #[test]
    fn the_key_and_the_attachment_are_as_rmw_zenoh_writes_them() {
        assert_eq!(
            joint_states_key(7, "press_0"),
            "7/press_0/joint_states/sensor_msgs::msg::dds_::JointState_/RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e"
        );
        let a = attachment(3, -2, &[9; 16]);
        assert_eq!(a.len(), 33);
        assert_eq!(a[..8], 3i64.to_le_bytes());
        assert_eq!(a[8..16], (-2i64).to_le_bytes());
        assert_eq!(a[16], 16);
        assert_eq!(a[17..], [9; 16]);
    }
}

#[cfg(test)]
mod graph {
    use super::*;

    /// Against xxHash's reference implementation (PyPI `xxhash` 3.5.0, `xxh3_128_intdigest`
    /// as 16 little-endian bytes), for the design document's talker and a token of ours.
    #[test]
    fn a_gid_is_the_xxh3_of_the_token_as_rmw_zenoh_makes_it() {
        let talker = "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/11/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,";
        let ours = publisher_token(
            42,
            "f44629142c9669e40414ac10d485415",
            1,
            "press_0",
            JOINT_STATES,
            JOINT_STATE_TYPE,
            JOINT_STATE_HASH,
        );
        let hex = |g: [u8; 16]| g.iter().map(|b| format!("{b:02x}")).collect::<String>();
        assert_eq!(hex(gid(talker)), "d2e5f27410cee403e2615e7eee6bcfef");
        assert_eq!(ours.len(), 216, "{ours}");
        assert_eq!(
            hex(gid(&ours)),
            "94b1435c6cdcabf5e2e2fea3ebc80cd2",
            "{ours}"
        );
    }

    #[test]
    fn the_graph_tokens_are_rmw_zenohs() {
        // As rmw_zenoh's design document writes a talker's (node `talker`, root namespace).
        let zid = "8b20917502ee955ac4476e0266340d5c";
        assert_eq!(
            format!("@ros2_lv/0/{zid}/0/0/NN/%/%/talker"),
            node_token(0, zid, "").replace(NODE, "talker")
        );
        assert_eq!(
            node_token(42, zid, "press_0"),
            format!("@ros2_lv/42/{zid}/0/0/NN/%/%press_0/rtc_gateway")
        );
        assert_eq!(
            publisher_token(
                42,
                zid,
                1,
                "press_0",
                JOINT_STATES,
                JOINT_STATE_TYPE,
                JOINT_STATE_HASH
            ),
            format!(
                "@ros2_lv/42/{zid}/0/1/MP/%/%press_0/rtc_gateway/%press_0%joint_states/\
                 sensor_msgs::msg::dds_::JointState_/{JOINT_STATE_HASH}/::,10:,:,:,,"
            )
        );
    }
}
