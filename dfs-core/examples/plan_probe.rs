use dfs_core::hand::HandModel;
use dfs_core::math::Isometry;
use dfs_core::operator::plan_grasp;
use dfs_core::scenario::Scenario;
fn main() {
    let hand = HandModel::glove10();
    for name in Scenario::BUILTINS {
        let s = Scenario::builtin(name, 0).unwrap();
        let (obj, _) = s.resolve().unwrap();
        let depth = match obj.shape {
            dfs_core::object::Shape::Sphere { radius } => radius,
            dfs_core::object::Shape::Box { half_extents } => half_extents[2],
            dfs_core::object::Shape::Cylinder { half_height, .. } => half_height,
        };
        let pose = Isometry::translation(0.0, 0.0, depth);
        let t = std::time::Instant::now();
        match plan_grasp(&hand, &obj, &pose, s.grasp) {
            Ok(p) => println!(
                "{name}: err {:.2} mm base {:?} q {:?} ({:?})",
                p.ik_error * 1e3,
                p.base.translation.vector.as_slice(),
                &p.q_grasp[..10],
                t.elapsed()
            ),
            Err(e) => println!("{name}: {e}"),
        }
    }
}
