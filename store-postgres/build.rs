//! Points sqlx's checked query macros of this crate at PostgreSQL data only.
//!
//! The macros read `DATABASE_URL` and `SQLX_OFFLINE` when they expand; in this workspace those
//! name the SQLite data base services' queries are checked against (`scripts/sqlx-prepare`
//! sets them for the whole build), which these PostgreSQL queries must never be described by.
//! So this crate sees its own variables instead, set for its compilation only:
//!
//! - by default, `SQLX_OFFLINE=true` and `SQLX_OFFLINE_DIR=store-postgres/.sqlx`: the queries
//!   build from the committed data, whatever the environment says;
//! - with `ICMS_POSTGRES_DATABASE_URL` set, they are described live against that data base
//!   (migrated with `migrations/postgres`), and their data written to
//!   `ICMS_POSTGRES_SQLX_OFFLINE_DIR` (or a directory under the build's `OUT_DIR`), which is how
//!   `scripts/sqlx-prepare` regenerates `store-postgres/.sqlx`.

fn main() {
    println!("cargo:rerun-if-env-changed=ICMS_POSTGRES_DATABASE_URL");
    println!("cargo:rerun-if-env-changed=ICMS_POSTGRES_SQLX_OFFLINE_DIR");
    println!("cargo:rerun-if-changed=build.rs");
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_else(|_| ".".to_owned());
    match std::env::var("ICMS_POSTGRES_DATABASE_URL") {
        Ok(url) if !url.is_empty() => {
            let dir = std::env::var("ICMS_POSTGRES_SQLX_OFFLINE_DIR").unwrap_or_else(|_| {
                let out = std::env::var("OUT_DIR").unwrap_or_else(|_| ".".to_owned());
                format!("{out}/sqlx-live")
            });
            let _ = std::fs::create_dir_all(&dir);
            println!("cargo:rustc-env=DATABASE_URL={url}");
            println!("cargo:rustc-env=SQLX_OFFLINE=false");
            println!("cargo:rustc-env=SQLX_OFFLINE_DIR={dir}");
        }
        _ => {
            println!("cargo:rustc-env=DATABASE_URL=");
            println!("cargo:rustc-env=SQLX_OFFLINE=true");
            println!("cargo:rustc-env=SQLX_OFFLINE_DIR={manifest}/.sqlx");
        }
    }
}
