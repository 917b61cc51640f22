//! `icms bench tick`: the held-object scenes (`fingertips`, and `power-grasp` with whole-hand
//! contact) print their figures and allocate nothing per tick, and the scenes the MuJoCo peer
//! reads (`benches/peers/fingertips_scene.json`, `power_grasp_scene.json`) are the DFS's. No test
//! asserts a time.

use crate::common;
use common::icms;

use std::path::Path;

use serde_json::Value;

fn json(out: &str) -> Value {
    serde_json::from_str(out).unwrap_or_else(|e| panic!("not JSON ({e}): {out}"))
}

/// `icms bench tick --scene SCENE --json --iterations 2000`'s report (the run must succeed).
fn tick_bench(scene: &str) -> Value {
    let (c, out, e) = icms(&[
        "bench",
        "tick",
        "--scene",
        scene,
        "--json",
        "--iterations",
        "2000",
    ]);
    assert_eq!(c, 0, "{e}");
    json(&out)
}

#[test]
fn the_fingertips_scene_prints_its_figures_without_allocating() {
    let r = tick_bench("fingertips");
    for field in ["median_ns", "p99_ns", "allocations_per_tick"] {
        assert!(r[field].is_number(), "no {field}: {r}");
    }
    assert!(r["median_ns"].as_f64().unwrap() > 0.0, "{r}");
    assert_eq!(r["allocations_per_tick"].as_f64(), Some(0.0), "{r}");
    assert_eq!(r["scene"], "fingertips");
    assert_eq!(r["iterations"], 2000);
    // Held through the run: the bench itself fails otherwise.
    assert!(r["min_contacts"].as_u64().unwrap() >= 3, "{r}");
}

#[test]
fn the_frozen_scene_of_issue_2_still_runs() {
    let r = tick_bench("frozen");
    assert_eq!(r["allocations_per_tick"].as_f64(), Some(0.0), "{r}");
    assert_eq!(r["contacts"], 4, "{r}");
}

#[test]
fn the_power_grasp_scene_holds_the_cylinder_with_whole_hand_contact_without_allocating() {
    let r = tick_bench("power-grasp");
    for field in ["median_ns", "p99_ns", "allocations_per_tick"] {
        assert!(r[field].is_number(), "no {field}: {r}");
    }
    assert_eq!(r["allocations_per_tick"].as_f64(), Some(0.0), "{r}");
    assert_eq!(r["scene"], "power-grasp");
    // Held through the run by the palm or a phalanx (the bench fails otherwise), on several
    // contacts.
    assert!(r["min_contacts"].as_u64().unwrap() >= 3, "{r}");
}

#[test]
fn the_power_grasp_scene_describes_the_settled_grasp_for_the_mujoco_peer() {
    let (c, out, e) = icms(&["bench", "tick", "--scene", "power-grasp", "--describe"]);
    assert_eq!(c, 0, "{e}");
    let r = json(&out);
    assert_eq!(r["scene"], "power-grasp");
    let contacts: Vec<&str> = r["contacts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    // The palm (its box or an eminence) presses.
    assert!(
        contacts
            .iter()
            .any(|c| ["palm", "thenar", "hypothenar"].contains(c)),
        "{contacts:?}"
    );
    assert_eq!(r["q"].as_array().unwrap().len(), 10);
}

/// Every number of `a` equal to `b`'s to 1e-12 (relative), every string and key the same.
fn same(a: &Value, b: &Value, at: &str) {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            assert!(
                (x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1.0),
                "{at}: {x} against {y}"
            );
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{at}");
            for (i, (x, y)) in x.iter().zip(y).enumerate() {
                same(x, y, &format!("{at}[{i}]"));
            }
        }
        (Value::Object(x), Value::Object(y)) => {
            let keys = |o: &serde_json::Map<String, Value>| o.keys().cloned().collect::<Vec<_>>();
            assert_eq!(keys(x), keys(y), "{at}");
            for (k, v) in x {
                same(v, &y[k], &format!("{at}.{k}"));
            }
        }
        _ => assert_eq!(a, b, "{at}"),
    }
}

/// The MuJoCo peer's scene file `benches/peers/{file}` is what `icms bench tick --scene
/// {scene} --describe` says today.
fn assert_peer_scene_is_the_dfss(scene: &str, file: &str) {
    let (c, out, e) = icms(&["bench", "tick", "--scene", scene, "--describe"]);
    assert_eq!(c, 0, "{e}");
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../benches/peers")
        .join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    same(
        &json(&out),
        &json(&text),
        &format!(
            "benches/peers/{file} (rewrite it with `icms bench tick --scene {scene} --describe`)"
        ),
    );
}

#[test]
fn the_mujoco_peer_reads_the_dfs_scene() {
    assert_peer_scene_is_the_dfss("fingertips", "fingertips_scene.json");
}

#[test]
fn the_mujoco_peers_power_grasp_scene_is_the_dfss() {
    assert_peer_scene_is_the_dfss("power-grasp", "power_grasp_scene.json");
}
