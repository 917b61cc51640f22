//! Compiles `proto/icms/session.proto` (the raw topics' schema of session format v2) with
//! protox (a protobuf compiler in Rust: no protoc to install) into a FileDescriptorSet, which
//! the recorder writes as the MCAP schema of each raw topic, and into prost types; and
//! `proto/icms/live.proto` (the binary frames of live sessions) into prost types alone.

use std::path::PathBuf;

fn main() {
    let proto = "proto/icms/session.proto";
    println!("cargo:rerun-if-changed={proto}");
    // sqlx::migrate! embeds ../migrations at compile time: a new migration must rebuild.
    println!("cargo:rerun-if-changed=../migrations");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let fds = protox::compile([proto], ["proto"]).unwrap_or_else(|e| panic!("{proto}: {e}"));
    // The schema written into files: the descriptor without source positions (readers do not
    // need them; the comments live in the .proto file).
    let mut bare = fds.clone();
    for f in &mut bare.file {
        f.source_code_info = None;
    }
    std::fs::write(
        out.join("icms_session.fds"),
        prost::Message::encode_to_vec(&bare),
    )
    .expect("writing the FileDescriptorSet");
    prost_build::Config::new()
        .out_dir(&out)
        .compile_fds(fds)
        .unwrap_or_else(|e| panic!("generating Rust from {proto}: {e}"));

    // Compiled apart: the session files' schema stays the session types alone.
    let live = "proto/icms/live.proto";
    println!("cargo:rerun-if-changed={live}");
    let fds = protox::compile([live], ["proto"]).unwrap_or_else(|e| panic!("{live}: {e}"));
    // Served at GET /api/v1/live/schema, so that a client builds the message classes with
    // nothing but a protobuf runtime (no protoc).
    let mut bare = fds.clone();
    for f in &mut bare.file {
        f.source_code_info = None;
    }
    std::fs::write(
        out.join("icms_live.fds"),
        prost::Message::encode_to_vec(&bare),
    )
    .expect("writing the live FileDescriptorSet");
    prost_build::Config::new()
        .out_dir(&out)
        .compile_fds(fds)
        .unwrap_or_else(|e| panic!("generating Rust from {live}: {e}"));
}
