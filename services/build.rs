//! Compiles `proto/icms/session.proto` (the raw topics' schema of session format v2) with
//! protox (a protobuf compiler in Rust: no protoc to install) into a FileDescriptorSet, which
//! the recorder writes as the MCAP schema of each raw topic, and into prost types; and
//! `proto/icms/live.proto` (the binary frames of live sessions) the same way, apart, so that
//! the session files' schema stays the session types alone (its FileDescriptorSet is served
//! at `GET /api/v1/live/schema`, for clients with a protobuf runtime and no protoc).

use std::path::{Path, PathBuf};

fn main() {
    // sqlx::migrate! embeds ../migrations at compile time: a new migration must rebuild.
    println!("cargo:rerun-if-changed=../migrations");
    // The store's checked queries (sqlx's `query!` macros) read the schema from the data base
    // at DATABASE_URL, or from the query data in ../.sqlx without one or with SQLX_OFFLINE:
    // a change to any of these must expand them again.
    println!("cargo:rerun-if-changed=../.sqlx");
    println!("cargo:rerun-if-env-changed=DATABASE_URL");
    println!("cargo:rerun-if-env-changed=SQLX_OFFLINE");
    println!("cargo:rerun-if-env-changed=SQLX_OFFLINE_DIR");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    compile("proto/icms/session.proto", &out, "icms_session.fds");
    compile("proto/icms/live.proto", &out, "icms_live.fds");
}

/// Compiles `proto` into prost types in `out` and its FileDescriptorSet into `out/fds_name`,
/// without source positions (readers do not need them; the comments live in the .proto file).
fn compile(proto: &str, out: &Path, fds_name: &str) {
    println!("cargo:rerun-if-changed={proto}");
    let fds = protox::compile([proto], ["proto"]).unwrap_or_else(|e| panic!("{proto}: {e}"));
    let mut bare = fds.clone();
    for f in &mut bare.file {
        f.source_code_info = None;
    }
    std::fs::write(out.join(fds_name), prost::Message::encode_to_vec(&bare))
        .unwrap_or_else(|e| panic!("writing the FileDescriptorSet of {proto}: {e}"));
    prost_build::Config::new()
        .out_dir(out)
        .compile_fds(fds)
        .unwrap_or_else(|e| panic!("generating Rust from {proto}: {e}"));
}
