//! The registry: a configuration selects a kinematics by name with numeric parameters, and
//! every mistake in it is named.

use kinematics::{BuildError, FiveBar, Kinematics, ParamError, Params, REGISTRY, build};

#[test]
fn every_registered_kinematics_builds_by_its_name_from_its_example() {
    for entry in REGISTRY {
        let name = entry.name;
        let k = entry
            .build_example()
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(k.name(), name);
        assert!(k.joints() >= 1 && !k.coords().is_empty());
        // The example gives only parameters the entry takes.
        for (param, _) in entry.example {
            assert!(entry.params.contains(param), "{name}: {param}");
        }
    }
    let names: Vec<_> = REGISTRY.iter().map(|e| e.name).collect();
    assert_eq!(names, ["gantry", "scara", "five-bar", "polar"]);
    // Those whose parameters are all optional build from their defaults too.
    for name in ["gantry", "polar"] {
        let k = build(name, &Params(&[])).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(k.name(), name);
    }
}

#[test]
fn the_five_bar_from_the_seeds_parameters_is_the_seeds() {
    let [l1, l2, l3, l4, l5] = FiveBar::SEED_LENGTHS;
    let params = [("l1", l1), ("l2", l2), ("l3", l3), ("l4", l4), ("l5", l5)];
    let built = build("five-bar", &Params(&params)).expect("the seed's");
    let q = [10.0, -5.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(
        built.axes_to_cartesian(&q),
        FiveBar::seed().axes_to_cartesian(&q)
    );
}

#[test]
fn an_unknown_type_lists_the_known_ones() {
    let err = build("delta", &Params(&[])).err().expect("unknown");
    assert_eq!(
        err,
        BuildError::UnknownType {
            name: "delta".into()
        }
    );
    assert_eq!(
        err.to_string(),
        "unknown kinematics type `delta`; the types are `gantry`, `scara`, `five-bar`, `polar`"
    );
}

#[test]
fn a_misspelt_parameter_is_named_with_the_known_ones() {
    let err = build("scara", &Params(&[("l1", 250.0), ("l_2", 150.0)]))
        .err()
        .expect("typo");
    assert_eq!(
        err,
        BuildError::Params {
            kinematics: "scara",
            error: ParamError::Unknown {
                name: "l_2".into(),
                known: &["l1", "l2"]
            },
        }
    );
    assert_eq!(
        err.to_string(),
        "kinematics `scara`: unknown parameter `l_2`; the parameters are `l1`, `l2`"
    );
}

#[test]
fn each_parameter_mistake_is_named() {
    let check = |name: &str, params: &[(&str, f64)], expected: ParamError| {
        match build(name, &Params(params)) {
            // Debug compares NaN too.
            Err(BuildError::Params { error, .. }) => {
                assert_eq!(
                    format!("{error:?}"),
                    format!("{expected:?}"),
                    "{name} {params:?}"
                )
            }
            Err(other) => panic!("{name} {params:?}: {other}"),
            Ok(_) => panic!("{name} {params:?} accepted"),
        }
    };
    check(
        "scara",
        &[("l1", 250.0)],
        ParamError::Missing { name: "l2" },
    );
    check(
        "scara",
        &[("l1", f64::NAN), ("l2", 1.0)],
        ParamError::NotFinite {
            name: "l1",
            value: f64::NAN,
        },
    );
    check(
        "scara",
        &[("l1", 250.0), ("l2", -1.0)],
        ParamError::NotPositive {
            name: "l2",
            value: -1.0,
        },
    );
    check(
        "scara",
        &[("l1", 1.0), ("l2", 1.0), ("l1", 2.0)],
        ParamError::Duplicate { name: "l1".into() },
    );
    check(
        "gantry",
        &[("axes", 2.5)],
        ParamError::Invalid {
            name: "axes",
            value: 2.5,
            expected: "1, 2 or 3 (x, y, theta)",
        },
    );
    let mut flat = FiveBar::EXAMPLE.to_vec();
    flat.retain(|(name, _)| *name != "assembly");
    flat.push(("assembly", 0.0));
    check(
        "five-bar",
        &flat,
        ParamError::Invalid {
            name: "assembly",
            value: 0.0,
            expected: "-1 (the seed's) or 1",
        },
    );
    check(
        "polar",
        &[("offset", f64::INFINITY)],
        ParamError::NotFinite {
            name: "offset",
            value: f64::INFINITY,
        },
    );
}
