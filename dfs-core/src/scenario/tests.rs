//! Tests of scenarios: files, scenes and built-ins.

use super::*;

#[test]
fn every_builtin_scenario_resolves() {
    for name in Scenario::BUILTINS {
        let s = Scenario::builtin(name, 3).unwrap();
        s.resolve().unwrap();
        assert!(s.duration() > 3.0);
    }
}

#[test]
fn bad_scenarios_name_the_field() {
    let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
    s.object.as_mut().unwrap().mass = -1.0;
    assert!(s.resolve().unwrap_err().to_string().contains("object.mass"));
    // Too light for the explicit object step (1 g diverged at lift-off): refused up front.
    s.object.as_mut().unwrap().mass = 0.001;
    let e = s.resolve().unwrap_err().to_string();
    assert!(e.contains("object.mass") && e.contains("0.005"), "{e}");
    s.object.as_mut().unwrap().mass = MIN_SIMULATED_MASS;
    assert!(s.resolve().is_ok());
    // A grasp file's ranges hold for scenario objects too: a 1e30 kg sphere or one 1 km
    // across is not a hand-held object.
    s.object.as_mut().unwrap().mass = 1e30;
    let e = s.resolve().unwrap_err().to_string();
    assert!(e.contains("object.mass"), "{e}");
    let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
    s.object.as_mut().unwrap().radius = Some(500.0);
    let e = s.resolve().unwrap_err().to_string();
    assert!(e.contains("object.radius"), "{e}");
    let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
    s.object.as_mut().unwrap().mu = -0.2;
    assert!(s.resolve().unwrap_err().to_string().contains("object.mu"));
    // And for friction: a grasp file refuses μ above 10 and μ_t above 1 m.
    let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
    s.object.as_mut().unwrap().mu = 1e6;
    let e = s.resolve().unwrap_err().to_string();
    assert!(e.contains("object.mu") && e.contains("[0.0, 10.0]"), "{e}");
    let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
    s.object.as_mut().unwrap().mu_torsion = 50.0;
    let e = s.resolve().unwrap_err().to_string();
    assert!(
        e.contains("object.mu_torsion") && e.contains("[0.0, 1.0] m"),
        "{e}"
    );
    // A lift height on a hold task was ignored.
    let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
    let hold = s.tasks.iter().position(|t| t.phase == Phase::Hold).unwrap();
    s.tasks[hold].height = Some(0.3);
    let e = s.resolve().unwrap_err().to_string();
    assert!(
        e.contains(&format!("tasks[{hold}].height")) && e.contains("a hold task takes no height"),
        "{e}"
    );
    let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
    s.tasks[hold].offset = Some([0.1, 0.0, 0.0]);
    let e = s.resolve().unwrap_err().to_string();
    assert!(e.contains(&format!("tasks[{hold}].offset")), "{e}");
    let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
    s.tasks[0].duration = 0.0;
    assert!(s
        .resolve()
        .unwrap_err()
        .to_string()
        .contains("tasks[0].duration"));
}

#[test]
fn a_script_longer_than_an_hour_is_refused_naming_the_tasks() {
    let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
    s.tasks = vec![
        Task {
            phase: Phase::Hold,
            duration: 600.0,
            height: None,
            offset: None,
            turn: None,
        };
        7
    ];
    let e = s.resolve().unwrap_err().to_string();
    assert!(e.contains("invalid tasks: the script lasts 4200 s"), "{e}");
    s.tasks.pop();
    s.resolve().unwrap();
}

fn hold(duration: Real) -> Task {
    Task {
        phase: Phase::Hold,
        duration,
        height: None,
        offset: None,
        turn: None,
    }
}

#[test]
fn a_script_of_more_than_256_tasks_is_refused_naming_the_tasks() {
    let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
    s.tasks = vec![hold(0.001); 100_000];
    let e = s.resolve().unwrap_err().to_string();
    assert_eq!(e, "invalid tasks: 100000 tasks; at most 256 are accepted");
    s.tasks = vec![hold(0.1); MAX_TASKS + 1];
    assert!(s.resolve().is_err());
    s.tasks.pop();
    s.resolve().unwrap();
}

#[test]
fn a_task_shorter_than_the_shortest_phase_is_refused_naming_it() {
    let mut s = Scenario::builtin("sphere-lift", 0).unwrap();
    s.tasks[3].duration = 0.001;
    let e = s.resolve().unwrap_err().to_string();
    assert_eq!(
        e,
        "invalid tasks[3].duration: 0.001 s is shorter than the shortest phase, 0.05 s"
    );
    s.tasks[3].duration = MIN_TASK_S;
    s.resolve().unwrap();
    s.tasks[3].duration = 601.0;
    let e = s.resolve().unwrap_err().to_string();
    assert!(
        e.contains("tasks[3].duration") && e.contains("(0, 600]"),
        "{e}"
    );
}

/// A scenario from JSON, or serde's message (the callers add the field's path).
fn parse(json: &serde_json::Value) -> std::result::Result<Scenario, String> {
    serde_json::from_value(json.clone()).map_err(|e| e.to_string())
}

#[test]
fn an_unknown_shape_or_phase_is_refused_when_the_file_is_read_naming_it() {
    let good = serde_json::json!({
        "name": "x",
        "object": {"shape": "sphere", "radius": 0.04, "mass": 0.3, "mu": 0.8},
        "tasks": [{"phase": "approach", "duration": 0.5}],
    });
    let s = parse(&good).unwrap();
    assert_eq!(s.object.as_ref().unwrap().shape, ShapeKind::Sphere);
    assert_eq!(s.tasks[0].phase, Phase::Approach);
    // Written back as it was read.
    let back = serde_json::to_value(&s).unwrap();
    assert_eq!(back["object"]["shape"], "sphere");
    assert_eq!(back["tasks"][0]["phase"], "approach");
    let mut bad = good.clone();
    bad["object"]["shape"] = "torus".into();
    let e = parse(&bad).unwrap_err();
    assert!(
        e.contains("unknown shape \"torus\"; expected one of sphere, box, cylinder"),
        "{e}"
    );
    let mut bad = good.clone();
    bad["tasks"][0]["phase"] = "juggle".into();
    let e = parse(&bad).unwrap_err();
    assert!(
        e.contains("unknown phase \"juggle\"; expected one of approach, preshape"),
        "{e}"
    );
    let mut bad = good;
    bad["grasp"] = "claw".into();
    let e = parse(&bad).unwrap_err();
    assert!(e.contains("unknown grasp style \"claw\""), "{e}");
}

#[test]
fn phases_and_grasp_styles_are_named_as_in_files_and_phases_order_by_name() {
    crate::names::assert_serde_agrees::<Phase>();
    crate::names::assert_serde_agrees::<GraspStyle>();
    let mut sorted = Phase::ALL;
    sorted.sort();
    let names: Vec<&str> = sorted.iter().map(|p| p.name()).collect();
    let mut alphabetical = names.clone();
    alphabetical.sort_unstable();
    assert_eq!(names, alphabetical);
    // A map keyed by phase writes its keys as a map keyed by name did.
    let by_phase: std::collections::BTreeMap<Phase, u8> =
        Phase::ALL.iter().map(|p| (*p, 0)).collect();
    let by_name: std::collections::BTreeMap<&str, u8> =
        Phase::ALL.iter().map(|p| (p.name(), 0)).collect();
    assert_eq!(
        serde_json::to_string(&by_phase).unwrap(),
        serde_json::to_string(&by_name).unwrap()
    );
}

/// A scene of a ball, a box and a cylinder, as a scenario file gives it.
fn three() -> serde_json::Value {
    serde_json::json!({
        "name": "three",
        "objects": [
            {"name": "ball", "shape": "sphere", "radius": 0.04, "mass": 0.3, "mu": 0.8,
             "position": [0.0, -0.2, 0.04]},
            {"name": "box", "shape": "box", "half_extents": [0.025, 0.025, 0.04],
             "mass": 0.2, "mu": 0.6, "position": [0.0, 0.0, 0.04], "yaw": 0.3},
            {"name": "cylinder", "shape": "cylinder", "radius": 0.035, "half_height": 0.09,
             "mass": 0.5, "mu": 0.7, "position": [0.0, 0.2, 0.09]},
        ],
        "target": "box",
        "tasks": [{"phase": "approach", "duration": 0.5}],
    })
}

fn scene_error(json: &serde_json::Value) -> String {
    parse(json)
        .unwrap()
        .resolve_scene()
        .unwrap_err()
        .to_string()
}

#[test]
fn a_scene_of_several_named_objects_resolves_with_its_target() {
    let s = parse(&three()).unwrap();
    let (scene, _) = s.resolve_scene().unwrap();
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["ball", "box", "cylinder"]);
    assert_eq!(scene.target, 1);
    assert_eq!(scene.target().name, "box");
    assert_eq!(scene.target().friction.mu, 0.6);
    assert_eq!(scene.table_height, 0.0);
    assert_eq!(scene.index_of("cylinder"), Some(2));
    assert_eq!(s.target_object().unwrap().name.as_deref(), Some("box"));
    let (target, _) = s.resolve().unwrap();
    assert_eq!(target, scene.target().object);
    assert_eq!(scene.dfs_objects().len(), 3);
    // Written back as it was read (with its defaults).
    let back = serde_json::to_value(&s).unwrap();
    assert_eq!(back["target"], "box");
    assert_eq!(back["objects"][2]["name"], "cylinder");
    assert_eq!(parse(&back).unwrap(), s);
    // A single object is named "object" unless named, and is its own target.
    let one = Scenario::builtin("sphere-lift", 0).unwrap();
    let (scene, _) = one.resolve_scene().unwrap();
    assert_eq!(
        (scene.objects.len(), scene.target().name.as_str()),
        (1, DEFAULT_OBJECT_NAME)
    );
    let back = serde_json::to_value(&one).unwrap();
    assert!(back.get("objects").is_none() && back.get("target").is_none());
    assert!(back["object"].get("name").is_none());
    let mut named = serde_json::to_value(&one).unwrap();
    named["object"]["name"] = "cup".into();
    named["target"] = "cup".into();
    let (scene, _) = parse(&named).unwrap().resolve_scene().unwrap();
    assert_eq!(scene.target().name, "cup");
    named["target"] = "mug".into();
    let e = scene_error(&named);
    assert!(e.contains("invalid target: \"mug\" names no object"), "{e}");
}

#[test]
fn objects_and_target_are_checked_naming_the_field() {
    let mut j = three();
    j["object"] = j["objects"][0].clone();
    let e = scene_error(&j);
    assert!(e.contains("invalid objects: give either `object`"), "{e}");
    let mut j = three();
    j.as_object_mut().unwrap().remove("objects");
    let e = scene_error(&j);
    assert!(e.contains("invalid object: missing"), "{e}");
    let mut j = three();
    j.as_object_mut().unwrap().remove("target");
    let e = scene_error(&j);
    assert!(
        e.contains("invalid target: missing") && e.contains("\"ball\", \"box\""),
        "{e}"
    );
    let mut j = three();
    j["target"] = "cup".into();
    assert!(scene_error(&j).contains("invalid target: \"cup\" names no object"));
    let mut j = three();
    j["objects"][2]["name"] = "ball".into();
    let e = scene_error(&j);
    assert!(
        e.contains("invalid objects[2].name: \"ball\" names objects[0] too"),
        "{e}"
    );
    for bad in ["", " ball", &"x".repeat(65), "a\nb"] {
        let mut j = three();
        j["objects"][1]["name"] = bad.into();
        j["target"] = bad.into();
        assert!(
            scene_error(&j).contains("invalid objects[1].name"),
            "{bad:?}"
        );
    }
    let mut j = three();
    j["objects"][1]["name"] = "é".repeat(64).into();
    j["target"] = "é".repeat(64).into();
    parse(&j).unwrap().resolve_scene().unwrap();
    let mut j = three();
    j["objects"][0].as_object_mut().unwrap().remove("name");
    assert!(scene_error(&j).contains("invalid objects[0].name: missing"));
    let mut j = three();
    j["objects"][2].as_object_mut().unwrap().remove("position");
    let e = scene_error(&j);
    assert!(e.contains("invalid objects[2].position: missing"), "{e}");
    // The object's own fields, under its path.
    let mut j = three();
    j["objects"][1]["mass"] = (-1.0).into();
    assert!(scene_error(&j).contains("invalid objects[1].mass"));
    let mut j = three();
    j["objects"][2]["half_height"] = serde_json::Value::Null;
    let e = scene_error(&j);
    assert!(e.contains("invalid objects[2].half_height"), "{e}");
    let mut j = three();
    j["objects"][0]["mu"] = 20.0.into();
    assert!(scene_error(&j).contains("invalid objects[0].mu"));
    // 1 to 8 objects.
    let mut j = three();
    j["objects"] = serde_json::json!([]);
    assert!(scene_error(&j).contains("invalid objects: 0 objects"));
    let mut j = three();
    let many: Vec<serde_json::Value> = (0..9)
        .map(|i| {
            let mut o = three()["objects"][0].clone();
            o["name"] = format!("ball{i}").into();
            o["position"] = serde_json::json!([0.0, 0.1 * i as f64, 0.04]);
            o
        })
        .collect();
    j["objects"] = many.into();
    j["target"] = "ball0".into();
    let e = scene_error(&j);
    assert!(
        e.contains("invalid objects: 9 objects; a scene holds 1 to 8"),
        "{e}"
    );
    j["objects"].as_array_mut().unwrap().pop();
    parse(&j).unwrap().resolve_scene().unwrap();
    // One object in the list: the target may be left out.
    let mut j = three();
    j["objects"].as_array_mut().unwrap().truncate(1);
    j.as_object_mut().unwrap().remove("target");
    let (scene, _) = parse(&j).unwrap().resolve_scene().unwrap();
    assert_eq!(scene.target().name, "ball");
    // A field no object takes.
    let mut j = three();
    j["objects"][1]["colour"] = "red".into();
    let e = parse(&j).unwrap_err();
    assert!(e.contains("unknown field `colour`"), "{e}");
}

#[test]
fn a_scene_of_overlapping_objects_is_refused_naming_both() {
    // The cylinder moved onto the box.
    let mut j = three();
    j["objects"][2]["position"] = serde_json::json!([0.05, 0.02, 0.09]);
    let e = scene_error(&j);
    assert!(
        e.contains("invalid objects[2].position")
            && e.contains("\"cylinder\" and \"box\" (objects[1]) overlap at their start"),
        "{e}"
    );
    // Beside the box, but closer than their sizes allow: the box is 2.5 cm half wide
    // (turned 0.3 rad: it reaches 3.1 cm along x), the cylinder 3.5 cm.
    let mut j = three();
    j["objects"][2]["position"] = serde_json::json!([0.062, 0.0, 0.09]);
    assert!(scene_error(&j).contains("overlap at their start"));
    j["objects"][2]["position"] = serde_json::json!([0.07, 0.0, 0.09]);
    parse(&j).unwrap().resolve_scene().unwrap();
    // Held above the box, clear of it, but falling onto it: they would overlap once both
    // rest on the table.
    let mut j = three();
    j["objects"][0]["position"] = serde_json::json!([0.0, 0.0, 0.3]);
    let e = scene_error(&j);
    assert!(
        e.contains("invalid objects[1].position")
            && e.contains("\"box\" and \"ball\" (objects[0]) overlap once both rest on the table"),
        "{e}"
    );
    // Diagonal neighbours whose bounding spheres overlap but whose shapes do not.
    let mut j = three();
    j["objects"][0] = serde_json::json!({"name": "crate", "shape": "box",
            "half_extents": [0.05, 0.05, 0.05], "mass": 0.5, "mu": 0.8,
            "position": [0.085, 0.085, 0.05]});
    j["objects"][1]["yaw"] = 0.0.into();
    parse(&j).unwrap().resolve_scene().unwrap();
}

#[test]
fn a_variant_perturbs_the_objects_within_their_ranges_and_varies_the_reaches() {
    assert!(Scenario::variant("juggle", 1).is_none());
    let within = |v: Real, base: Real, (lo, hi): (Real, Real)| {
        (base * lo - 1e-12..=base * hi + 1e-12).contains(&v)
    };
    let mut targets = std::collections::BTreeSet::new();
    let mut masses = std::collections::BTreeSet::new();
    for name in Scenario::BUILTINS {
        for seed in 0..30 {
            let v = Scenario::variant(name, seed).unwrap();
            let b = Scenario::builtin(name, seed).unwrap();
            assert_eq!(
                Scenario::variant(name, seed).unwrap(),
                v,
                "the same each time"
            );
            assert!(v.vary_reach && !b.vary_reach);
            assert_eq!(
                (&v.name, &v.tasks, v.seed, v.operator_mu),
                (&b.name, &b.tasks, b.seed, b.operator_mu)
            );
            v.resolve_scene().unwrap();
            // Written with the flag, and read back as it was.
            let json = serde_json::to_value(&v).unwrap();
            assert_eq!(json["vary_reach"], true);
            assert_eq!(parse(&json).unwrap(), v);
            let pairs: Vec<(&ScenarioObject, &ScenarioObject)> =
                match (&v.object, &b.object, &v.objects, &b.objects) {
                    (Some(x), Some(y), None, None) => vec![(x, y)],
                    (None, None, Some(x), Some(y)) => x.iter().zip(y).collect(),
                    _ => panic!("{name}: the variant keeps the scene's form"),
                };
            for (o, base) in pairs {
                masses.insert(o.mass.to_bits());
                assert!(within(o.mass, base.mass, VARIANT_MASS_SCALE), "{name}");
                assert!(within(o.mu, base.mu, VARIANT_MU_SCALE), "{name}");
                for (x, y) in o.radius.iter().zip(&base.radius).chain(
                    o.half_extents
                        .iter()
                        .flatten()
                        .zip(base.half_extents.iter().flatten()),
                ) {
                    assert!(within(*x, *y, VARIANT_SIZE_SCALE), "{name}");
                }
                if let (Some(x), Some(y)) = (o.half_height, base.half_height) {
                    assert!(within(x, y, VARIANT_SIZE_SCALE), "{name}");
                }
                assert_eq!(
                    (&o.name, o.shape, o.yaw),
                    (&base.name, base.shape, base.yaw)
                );
                if let (Some(p), Some(q)) = (o.position, base.position) {
                    // Shifted by at most the jitter, resting on the table.
                    assert!((p[0] - q[0]).abs() <= VARIANT_JITTER_M + 1e-12);
                    assert!((p[1] - q[1]).abs() <= VARIANT_JITTER_M + 1e-12);
                    let depth = o.to_shape().unwrap().support_depth(&Rotation::identity());
                    assert!((p[2] - depth).abs() < 1e-12, "{name}");
                }
            }
            if let Some(t) = &v.target {
                let style = match v.target_object().unwrap().shape {
                    ShapeKind::Cylinder => GraspStyle::Power,
                    _ => GraspStyle::Pinch,
                };
                assert_eq!(v.grasp, style);
                targets.insert(t.clone());
            } else {
                assert_eq!(v.grasp, b.grasp);
            }
        }
    }
    assert_eq!(
        targets.into_iter().collect::<Vec<_>>(),
        ["ball", "box", "cylinder"]
    );
    assert!(masses.len() > 100, "the masses vary");
}

#[test]
fn every_builtin_task_is_within_the_task_limits() {
    for name in Scenario::BUILTINS {
        let s = Scenario::builtin(name, 0).unwrap();
        assert!(s.tasks.len() <= MAX_TASKS, "{name}");
        for t in &s.tasks {
            assert!((MIN_TASK_S..=MAX_TASK_S).contains(&t.duration), "{name}");
        }
    }
}
