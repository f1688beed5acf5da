use control_plane::failure::*;

#[test]
fn a_failure_travels_as_json_and_reads_as_before() {
    let f = Failure::LatchedAfterMotion {
        estop: Box::new(Failure::Estop {
            origin: control_plane::info::Origin::External,
            by: "iobridge".into(),
            code: shm_schema::event::code::ESTOP_INPUT,
            reason: "estop_ok opened".into(),
            event: None,
        }),
    };
    let json = serde_json::to_string(&f).expect("json");
    assert!(
        json.starts_with(r#"{"latched-after-motion":{"estop":{"estop":"#),
        "{json}"
    );
    assert_eq!(serde_json::from_str::<Failure>(&json).expect("back"), f);
    let bytes = postcard::to_allocvec(&f).expect("postcard");
    assert_eq!(postcard::from_bytes::<Failure>(&bytes).expect("back"), f);
    assert!(f.to_string().starts_with(
        "e-stop (external) raised by iobridge: estop_ok opened\n  the motion completed"
    ));
}
