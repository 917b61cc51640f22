//! `icms dfs-static`: static force analysis of a grasp file or a built-in grasp.

use super::{print_json, CliError};
use dfs_core::spec::GraspSpec;
use dfs_core::statics::analyse;
use std::path::Path;

/// Arguments of `icms dfs-static`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A built-in grasp (`paper-sphere`) or a grasp file (JSON, format in docs/skills.md).
    #[arg(long)]
    grasp: String,
    /// The operator pushes `scale` times the intensities that hold the object.
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Print JSON (otherwise a table).
    #[arg(long)]
    json: bool,
}

/// Loads a grasp by built-in name or from a JSON file; errors name the file and the field.
pub fn load_grasp(name_or_path: &str) -> Result<GraspSpec, CliError> {
    if let Some(g) = GraspSpec::builtin(name_or_path) {
        return Ok(g);
    }
    let path = Path::new(name_or_path);
    if !path.exists() {
        return Err(CliError(format!(
            "no built-in grasp or file named {name_or_path:?} (built-in: {})",
            GraspSpec::BUILTINS.join(", ")
        )));
    }
    let text =
        std::fs::read_to_string(path).map_err(|e| CliError(format!("{}: {e}", path.display())))?;
    super::parse_json(&text)
        .map_err(|e| CliError(format!("{}: invalid grasp file: {e}", path.display())))
}

/// Runs the analysis and prints it.
pub fn run(a: Args) -> Result<(), CliError> {
    let spec = load_grasp(&a.grasp)?;
    let r = analyse(&spec, a.scale).map_err(|e| CliError(format!("{}: {e}", a.grasp)))?;
    if a.json {
        return print_json(&r);
    }
    println!("contact  normal_force  tangential_force  in_cone");
    for (i, c) in r.contacts.iter().enumerate() {
        println!(
            "{i:>7}  {:>12.4}  {:>16.4}  {}",
            c.normal_force, c.tangential_force, c.in_cone
        );
    }
    println!("object_force        {:?}", r.object_force);
    println!("f_ext               {:?}", r.f_ext);
    println!("object_acceleration {:?}", r.object_acceleration);
    match (&r.optimised, &r.optimised_reason) {
        (Some(o), _) => println!(
            "optimised: total normal force {:.4} N (margin {})",
            o.total_normal_force, o.margin
        ),
        (None, Some(reason)) => println!("optimised: infeasible: {reason}"),
        _ => {}
    }
    for w in &r.warnings {
        println!("warning: {w}");
    }
    Ok(())
}
