use control_plane::status::*;

/// The IO part of a status crosses the control channel (postcard) whole, and stays
/// untagged in JSON: `0`, `1`, `"hold"`.
#[test]
fn io_entries_cross_postcard_tagged_and_json_as_documented() {
    let values = [
        SafeValue::Level(0),
        SafeValue::Level(1),
        SafeValue::Hold(HoldWord::Hold),
    ];
    for v in values {
        let bytes = postcard::to_allocvec(&v).expect("postcard");
        assert_eq!(postcard::from_bytes::<SafeValue>(&bytes).expect("back"), v);
    }
    let json: Vec<String> = values
        .iter()
        .map(|v| serde_json::to_string(v).expect("json"))
        .collect();
    assert_eq!(json, ["0", "1", "\"hold\""]);
    for (v, j) in values.iter().zip(&json) {
        assert_eq!(serde_json::from_str::<SafeValue>(j).expect("back"), *v);
    }
    let io = IoEntry::Output {
        name: "gripper".into(),
        value: Some(1),
        safe: SafeValue::Hold(HoldWord::Hold),
    };
    let bytes = postcard::to_allocvec(&io).expect("postcard");
    assert_eq!(postcard::from_bytes::<IoEntry>(&bytes).expect("back"), io);
    let json = serde_json::to_string(&io).expect("json");
    assert_eq!(
        json,
        r#"{"direction":"output","name":"gripper","value":1,"safe":"hold"}"#
    );
    assert_eq!(serde_json::from_str::<IoEntry>(&json).expect("back"), io);
}

/// A value that is not finite (a fault's limit) crosses postcard as it is; JSON, which has
/// none, says `null` as it always did.
#[test]
fn a_fault_that_is_not_finite_crosses_postcard() {
    let fault = ServoFault {
        code: 1,
        name: "x".into(),
        axis: None,
        value: f64::NAN,
        limit: f64::INFINITY,
    };
    let bytes = postcard::to_allocvec(&fault).expect("postcard");
    let back: ServoFault = postcard::from_bytes(&bytes).expect("back");
    assert!(back.value.is_nan() && back.limit == f64::INFINITY);
}
