//! `icms dfs-static` end to end: the binary as a user runs it.

use crate::common;
use common::icms;

use serde_json::Value;

fn vec6(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

#[test]
fn paper_sphere_reproduces_the_notes_table_and_balances_gravity() {
    let (code, out, err) = icms(&["dfs-static", "--grasp", "paper-sphere", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    assert!(close(
        &vec6(&v["object_force"]),
        &[0.0, 0.0, 9.81, 0.0, 0.0, 0.0],
        1e-9
    ));
    let table = [
        (1.197, 1.550),
        (0.954, 1.229),
        (1.197, 1.550),
        (2.660, 3.427),
    ];
    let contacts = v["contacts"].as_array().unwrap();
    assert_eq!(contacts.len(), 4);
    for (c, (n, t)) in contacts.iter().zip(table) {
        let cn = c["normal_force"].as_f64().unwrap();
        let ct = c["tangential_force"].as_f64().unwrap();
        assert!(
            (cn - n).abs() / n < 0.01 && (ct - t).abs() / t < 0.01,
            "{cn} {ct}"
        );
        assert_eq!(c["in_cone"], Value::Bool(true));
        for key in ["position", "normal", "intensity"] {
            assert!(c[key].is_array(), "{key}");
        }
    }
    assert!(v["optimised"].is_object());
    assert!(v["object_acceleration"].is_array());
}

#[test]
fn pushing_one_and_a_half_times_harder_gives_the_papers_f_ext_and_the_static_feedback() {
    let (_, s, _) = icms(&["dfs-static", "--grasp", "paper-sphere", "--json"]);
    let (code, out, _) = icms(&[
        "dfs-static",
        "--grasp",
        "paper-sphere",
        "--scale",
        "1.5",
        "--json",
    ]);
    assert_eq!(code, 0);
    let s: Value = serde_json::from_str(&s).unwrap();
    let v: Value = serde_json::from_str(&out).unwrap();
    assert!(close(
        &vec6(&v["f_ext"]),
        &[0.0, 0.0, 4.905, 0.0, 0.0, 0.0],
        1e-9
    ));
    assert!(close(
        &vec6(&v["object_force"]),
        &[0.0, 0.0, 14.715, 0.0, 0.0, 0.0],
        1e-9
    ));
    for (a, b) in v["contacts"]
        .as_array()
        .unwrap()
        .iter()
        .zip(s["contacts"].as_array().unwrap())
    {
        assert!(close(&vec6(&a["feedback"]), &vec6(&b["feedback"]), 1e-9));
    }
}

#[test]
fn a_grasp_file_with_low_friction_reports_an_infeasible_optimisation_or_slip() {
    let dir = std::env::temp_dir().join(format!("icms-grasp-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("pinch.json");
    // Two antipodal frictionless contacts cannot carry a vertical load.
    std::fs::write(
        &file,
        r#"{"object": {"shape": "box", "half_extents": [0.03, 0.03, 0.03], "mass": 0.5},
            "contact_model": "frictionless", "mu": 0.0,
            "contacts": [{"position": [0.03, 0, 0]}, {"position": [-0.03, 0, 0]}]}"#,
    )
    .unwrap();
    let (code, out, err) = icms(&["dfs-static", "--grasp", file.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    assert!(v["optimised"].is_null());
    assert!(
        v["optimised_reason"]
            .as_str()
            .unwrap()
            .contains("infeasible")
            || !v["optimised_reason"].as_str().unwrap().is_empty()
    );
    assert!(vec6(&v["object_acceleration"])[2] < 0.0, "the box falls");
}

#[test]
fn malformed_grasp_files_fail_with_a_message_naming_the_field() {
    let dir = std::env::temp_dir().join(format!("icms-bad-grasp-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cases = [
        (
            r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": -1}, "mu": 1, "contacts": [{"position": [0,0,-0.1]}]}"#,
            "object.mass",
        ),
        (
            r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": 1}, "mu": -1, "contacts": [{"position": [0,0,-0.1]}]}"#,
            "mu",
        ),
        (
            r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": 1}, "contacts": [{"position": [0,0,-0.1]}]}"#,
            "mu",
        ),
        (
            r#"{"object": {"shape": "cone", "radius": 0.1, "mass": 1}, "mu": 1, "contacts": [{"position": [0,0,-0.1]}]}"#,
            "object.shape",
        ),
        (
            r#"{"object": {"shape": "sphere", "mass": 1}, "mu": 1, "contacts": [{"position": [0,0,-0.1]}]}"#,
            "object.radius",
        ),
        (
            r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": 1}, "mu": 1, "contacts": []}"#,
            "contacts",
        ),
        (
            r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": 1}, "mu": 1, "contacts": [{"position": [0,0]}]}"#,
            "position",
        ),
        (
            r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": 1}, "mu": 1, "contact_model": "sticky", "contacts": [{"position": [0,0,-0.1]}]}"#,
            "sticky",
        ),
        (r#"{"object": "#, "EOF"),
        // A normal pointing out of the object was taken and the contact said to pull.
        (
            r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": 1}, "mu": 1, "contacts": [{"position": [0,0,-0.1], "normal": [0,0,-1]}]}"#,
            "contacts[0].normal",
        ),
        // Content after the grasp was ignored (exit 0); over HTTP it is refused.
        (
            r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": 1}, "mu": 1, "contacts": [{"position": [0,0,-0.1]}]} trailing"#,
            "trailing characters",
        ),
    ];
    for (i, (text, field)) in cases.iter().enumerate() {
        let file = dir.join(format!("bad{i}.json"));
        std::fs::write(&file, text).unwrap();
        let (code, out, err) = icms(&["dfs-static", "--grasp", file.to_str().unwrap(), "--json"]);
        assert_ne!(code, 0, "case {i} must fail: {out}");
        assert!(err.contains(field), "case {i}: {err:?} should name {field}");
        assert!(!err.contains("panicked"), "{err}");
    }
    let (code, _, err) = icms(&["dfs-static", "--grasp", "no-such-grasp", "--json"]);
    assert_ne!(code, 0);
    assert!(err.contains("paper-sphere"), "{err}");
}

#[test]
fn one_contact_and_collinear_contacts_are_reported_as_degenerate() {
    let dir = std::env::temp_dir().join(format!("icms-degenerate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (name, contacts) in [
        ("one", r#"[{"position": [0, 0, -0.1]}]"#),
        (
            "line",
            r#"[{"position": [0.1, 0, 0]}, {"position": [-0.1, 0, 0]}]"#,
        ),
    ] {
        let file = dir.join(format!("{name}.json"));
        std::fs::write(&file, format!(r#"{{"object": {{"shape": "sphere", "radius": 0.1, "mass": 1}}, "mu": 0.8, "contacts": {contacts}}}"#)).unwrap();
        let (code, out, err) = icms(&["dfs-static", "--grasp", file.to_str().unwrap(), "--json"]);
        assert_eq!(code, 0, "{err}");
        let v: Value = serde_json::from_str(&out).unwrap();
        assert!(!v["warnings"].as_array().unwrap().is_empty(), "{name}");
        assert!(v["grasp_rank"].as_u64().unwrap() < 6);
    }
}

/// Writes `text` as a grasp file in a fresh directory and runs `icms dfs-static` on it.
fn run_grasp(name: &str, text: &str, extra: &[&str]) -> (i32, String, String) {
    let dir = std::env::temp_dir().join(format!("icms-static-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join(format!("{name}.json"));
    std::fs::write(&file, text).unwrap();
    let mut args = vec!["dfs-static", "--grasp", file.to_str().unwrap(), "--json"];
    args.extend_from_slice(extra);
    icms(&args)
}

/// The paper's sphere with `object` and `extra` fields spliced in.
fn sphere_grasp(object: &str, extra: &str, first_contact: &str) -> String {
    format!(
        r#"{{"object": {object}, "mu": 1.5, "contacts": [{{"position": {first_contact}}}, {{"position": [0, 0.076, -0.059]}}, {{"position": [-0.054, 0.054, -0.059]}}, {{"position": [0, -0.076, -0.059]}}]{extra}}}"#
    )
}

const SPHERE: &str = r#"{"shape": "sphere", "radius": 0.1, "mass": 1.0}"#;
const FIRST: &str = "[0.054, 0.054, -0.059]";

#[test]
fn huge_but_finite_numbers_are_refused_naming_the_field_and_its_range() {
    let cases = [
        (
            "hugemass",
            sphere_grasp(
                r#"{"shape": "sphere", "radius": 0.1, "mass": 1e300}"#,
                "",
                FIRST,
            ),
            "object.mass",
        ),
        (
            "gravity",
            sphere_grasp(SPHERE, r#", "gravity": [0, 0, -1e308]"#, FIRST),
            "gravity",
        ),
        (
            "bigpos",
            sphere_grasp(SPHERE, "", "[1e308, 1e308, 1e308]"),
            "contacts[0].position",
        ),
        (
            "tinyradius",
            sphere_grasp(
                r#"{"shape": "sphere", "radius": 1e-300, "mass": 1.0}"#,
                "",
                FIRST,
            ),
            "object.radius",
        ),
        (
            "bigmu",
            sphere_grasp(SPHERE, "", FIRST).replace("1.5", "1e12"),
            "mu",
        ),
    ];
    for (name, text, field) in &cases {
        let (code, out, err) = run_grasp(name, text, &[]);
        assert_eq!(code, 1, "{name} must fail: {out}");
        assert!(
            err.contains(field) && err.contains("must be"),
            "{name}: {err}"
        );
        assert!(
            out.is_empty() && !err.contains("panicked"),
            "{name}: {out} {err}"
        );
    }
    let (code, out, err) = icms(&[
        "dfs-static",
        "--grasp",
        "paper-sphere",
        "--scale",
        "1e308",
        "--json",
    ]);
    assert_eq!(code, 1, "{out}");
    assert!(err.contains("scale") && err.contains("100"), "{err}");
}

#[test]
fn contacts_off_the_surface_are_refused_naming_the_contact_and_its_distance() {
    for (name, first, distance) in [
        ("offsurf", "[0.5, 0.5, 0.5]", "7.6603e-1 m"),
        ("centre", "[0, 0, 0]", "1.0000e-1 m"),
    ] {
        let (code, out, err) = run_grasp(name, &sphere_grasp(SPHERE, "", first), &[]);
        assert_eq!(code, 1, "{name}: {out}");
        assert!(
            err.contains("contacts[0].position")
                && err.contains("not on the surface")
                && err.contains(distance),
            "{name}: {err}"
        );
    }
    // The built-in grasps stay valid.
    let (code, _, err) = icms(&["dfs-static", "--grasp", "paper-sphere", "--json"]);
    assert_eq!(code, 0, "{err}");
}

#[test]
fn contacts_carrying_no_force_are_in_their_cones_and_not_pulling() {
    let (code, out, err) = run_grasp(
        "g0",
        &sphere_grasp(SPHERE, r#", "gravity": [0, 0, 0]"#, FIRST),
        &[],
    );
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    for section in [&v["contacts"], &v["optimised"]["contacts"]] {
        for c in section.as_array().unwrap() {
            assert_eq!(c["in_cone"], Value::Bool(true), "{c}");
        }
    }
    assert!(
        v["warnings"].as_array().unwrap().is_empty(),
        "{}",
        v["warnings"]
    );
    let (code, out, err) = run_grasp(
        "fl6box",
        r#"{"object": {"shape": "box", "half_extents": [0.05, 0.05, 0.05], "mass": 1.0}, "contact_model": "frictionless",
            "contacts": [{"position": [0.05, 0, 0]}, {"position": [-0.05, 0, 0]}, {"position": [0, 0.05, 0]},
                         {"position": [0, -0.05, 0]}, {"position": [0, 0, -0.05]}, {"position": [0, 0, 0.05]}]}"#,
        &[],
    );
    assert_eq!(code, 0, "a frictionless grasp needs no mu: {err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    let in_cone: Vec<&Value> = v["contacts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| &c["in_cone"])
        .collect();
    assert_eq!(in_cone, [true, true, true, true, true, false]);
    let warnings = v["warnings"].to_string();
    assert!(
        warnings.contains("contact 5 would have to pull") && !warnings.contains("0.0000 N"),
        "{warnings}"
    );
    assert!(v["optimised"]["contacts"]
        .as_array()
        .unwrap()
        .iter()
        .all(|c| c["in_cone"] == Value::Bool(true)));
}

#[test]
fn a_grasp_file_that_is_not_a_json_object_is_refused_in_user_words() {
    for (name, text) in [
        (
            "arr7",
            r#"[{"shape":"sphere","radius":0.1,"mass":1.0},[0,0,-9.81],"point_with_friction",1.5,0.0,[{"position":[0,0,-0.1]}],[0,0,0,0,0,0]]"#,
        ),
        ("array", "[]"),
        ("null", "null"),
    ] {
        let (code, out, err) = run_grasp(name, text, &[]);
        assert_eq!(code, 1, "{name}: {out}");
        assert!(
            err.contains("expected a grasp file: a JSON object") && !err.contains("struct"),
            "{name}: {err}"
        );
    }
    let (code, _, err) = run_grasp(
        "contact-array",
        r#"{"object": {"shape": "sphere", "radius": 0.1, "mass": 1}, "mu": 1, "contacts": [[[0, 0, -0.1]]]}"#,
        &[],
    );
    assert_eq!(code, 1);
    assert!(
        err.contains("contacts[0]") && err.contains("expected a contact"),
        "{err}"
    );
}
