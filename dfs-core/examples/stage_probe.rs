use dfs_core::dfs::GloveSample;
use dfs_core::fixtures::glove10_holding_paper_sphere;
use std::time::Instant;
fn main() {
    let (mut dfs, q, tau, base) = glove10_holding_paper_sphere().unwrap();
    let start = *dfs.object_state();
    let s = GloveSample {
        q: &q,
        tau: &tau,
        base,
    };
    let n = 100000;
    let hand = dfs.hand().clone();
    let mut kin = dfs_core::hand::Kinematics::default();
    let mut m = dfs_core::hand::DofMatrix::identity();
    let t = Instant::now();
    for _ in 0..n {
        hand.forward_kinematics(&base, &q, &mut kin);
    }
    println!("fk {:?}", t.elapsed() / n);
    let t = Instant::now();
    for _ in 0..n {
        hand.tip_jacobians(&mut kin);
    }
    println!("jac {:?}", t.elapsed() / n);
    let t = Instant::now();
    for _ in 0..n {
        hand.mass_matrix(&kin, &mut m);
    }
    println!("mass {:?}", t.elapsed() / n);
    let t = Instant::now();
    for _ in 0..n {
        dfs.set_object_state(start);
        dfs.stage_glove(&s).unwrap();
    }
    println!("glove {:?}", t.elapsed() / n);
    let t = Instant::now();
    for _ in 0..n {
        dfs.stage_contacts();
    }
    println!("contacts {:?}", t.elapsed() / n);
    let t = Instant::now();
    for _ in 0..n {
        dfs.stage_forces(&tau);
    }
    println!("forces {:?}", t.elapsed() / n);
    let t = Instant::now();
    for _ in 0..n {
        dfs.set_object_state(start);
        dfs.stage_object();
    }
    println!("object {:?}", t.elapsed() / n);
    let t = Instant::now();
    for _ in 0..n {
        dfs.stage_feedback(&tau);
    }
    println!("feedback {:?}", t.elapsed() / n);
}
