use dfs_core::hand::HandModel;
use dfs_core::operator::Simulation;
use dfs_core::scenario::Scenario;
fn main() {
    let name = std::env::args().nth(1).unwrap_or("box-pinch-lift".into());
    let s = Scenario::builtin(&name, 1).unwrap();
    let mut sim = Simulation::new(&s, HandModel::glove10(), None).unwrap();
    let t0 = std::time::Instant::now();
    let mut last = None;
    while sim.step().unwrap() {
        let t = sim.ticks();
        if t % 100 == 0 {
            let o = sim.output();
            let p = sim.dfs().object_state().pose.translation.vector;
            let (_, tau, base) = sim.sample();
            let rel = base.inverse() * sim.dfs().object_state().pose;
            let phase = sim.phase();
            if last != Some(phase) {
                println!("--- {:?}", phase);
                last = Some(phase);
            }
            let cs: Vec<String> = (0..o.n_tips)
                .map(|k| {
                    let c = o.tips[k];
                    format!(
                        "{}{}{:.2}",
                        if c.in_contact {
                            "C"
                        } else if c.touching {
                            "t"
                        } else {
                            "."
                        },
                        if c.slip { "s" } else { "" },
                        c.intensity[2]
                    )
                })
                .collect();
            println!(
                "t={:.1} obj z={:.4} rel=({:.4},{:.4},{:.4}) v={:.4} n={} [{}] tau_max={:.2}",
                t as f64 / 1000.0,
                p.z,
                rel.translation.x,
                rel.translation.y,
                rel.translation.z,
                sim.dfs().object_state().linear_velocity.norm(),
                o.n_contacts,
                cs.join(" "),
                tau.iter().fold(0.0f64, |m, v| m.max(v.abs()))
            );
        }
    }
    println!("elapsed {:?}", t0.elapsed());
}
