//! Decompression bombs: small MCAP files whose chunks expand to gigabytes (zstd and lz4 of
//! zeros, headers that lie about their size, many chunks each under the record limit) are
//! refused before they are decompressed, naming the limit, and reading one holds no more memory
//! than [`ReadLimits::decompressed_limit`] of its length (measured as the peak resident set of a
//! child process that reads it).

use std::io::Write;
use std::path::Path;
use std::process::Command;

use services::mcap_io::{read_session_bytes, read_session_file, salvage, ReadLimits};
use services::RecordingError;

const MAGIC: &[u8] = b"\x89MCAP0\r\n";
const MIB: usize = 1 << 20;

/// A record: opcode, length, body.
fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
    let mut r = vec![opcode];
    r.extend_from_slice(&(body.len() as u64).to_le_bytes());
    r.extend_from_slice(body);
    r
}

/// An MCAP string: u32 length, bytes.
fn string(s: &str) -> Vec<u8> {
    let mut r = (s.len() as u32).to_le_bytes().to_vec();
    r.extend_from_slice(s.as_bytes());
    r
}

/// Chunk content of `len` bytes: one message on channel 1 whose payload is zeros.
fn zero_message(len: usize) -> Vec<u8> {
    let header = 2 + 4 + 8 + 8;
    let mut body = vec![0u8; len - 9];
    body[..2].copy_from_slice(&1u16.to_le_bytes());
    assert!(body.len() >= header);
    record(0x05, &body)
}

/// Chunk content of about `len` bytes: messages on channel 1 with the 2-byte payload `{}`.
fn tiny_messages(len: usize) -> Vec<u8> {
    let mut body = vec![0u8; 2 + 4 + 8 + 8];
    body[..2].copy_from_slice(&1u16.to_le_bytes());
    body.extend_from_slice(b"{}");
    let one = record(0x05, &body);
    one.repeat(len / one.len())
}

/// A file of 60 zstd chunks of 1 MiB of [`tiny_messages`] and 0.5 MiB of padding (a private
/// record): the chunks' declared sizes are within the budget of its length, their 1.9 million
/// messages' index is not.
fn tiny_message_file() -> Vec<u8> {
    let content = tiny_messages(MIB);
    let compressed = Compression::Zstd.compress(&content);
    let padding = record(0x80, &vec![0u8; MIB / 2]);
    let chunks = (0..60).map(|_| chunk(&compressed, content.len() as u64, Compression::Zstd));
    mcap_file(std::iter::once(padding).chain(chunks))
}

#[derive(Clone, Copy, Debug)]
enum Compression {
    /// zstd, the frame declaring its content size.
    Zstd,
    /// zstd from a streaming encoder: the frame does not say how large it is.
    ZstdStream,
    Lz4,
}

impl Compression {
    fn name(self) -> &'static str {
        match self {
            Compression::Zstd | Compression::ZstdStream => "zstd",
            Compression::Lz4 => "lz4",
        }
    }

    fn compress(self, data: &[u8]) -> Vec<u8> {
        match self {
            Compression::Zstd => zstd::bulk::compress(data, 3).unwrap(),
            Compression::ZstdStream => {
                let mut e = zstd::stream::Encoder::new(Vec::new(), 3).unwrap();
                e.write_all(data).unwrap();
                e.finish().unwrap()
            }
            Compression::Lz4 => {
                let mut e = lz4::EncoderBuilder::new()
                    .level(9)
                    .build(Vec::new())
                    .unwrap();
                e.write_all(data).unwrap();
                let (out, result) = e.finish();
                result.unwrap();
                out
            }
        }
    }
}

/// A chunk record holding `compressed`, its header declaring `declared` bytes of content (no
/// CRC).
fn chunk(compressed: &[u8], declared: u64, compression: Compression) -> Vec<u8> {
    let mut body = Vec::new();
    body.extend_from_slice(&0u64.to_le_bytes());
    body.extend_from_slice(&0u64.to_le_bytes());
    body.extend_from_slice(&declared.to_le_bytes());
    body.extend_from_slice(&0u32.to_le_bytes());
    body.extend_from_slice(&string(compression.name()));
    body.extend_from_slice(&(compressed.len() as u64).to_le_bytes());
    body.extend_from_slice(compressed);
    record(0x06, &body)
}

/// A complete MCAP file (header, a channel `/bomb` with id 1, the records given (chunks), data
/// end, footer) with no CRCs and no summary: everything a reader accepts up to the chunks'
/// content.
fn mcap_file(chunks: impl IntoIterator<Item = Vec<u8>>) -> Vec<u8> {
    let mut f = MAGIC.to_vec();
    f.extend(record(0x01, &[string(""), string("bomb")].concat()));
    let mut channel = Vec::new();
    channel.extend_from_slice(&1u16.to_le_bytes());
    channel.extend_from_slice(&0u16.to_le_bytes());
    channel.extend(string("/bomb"));
    channel.extend(string("json"));
    channel.extend_from_slice(&0u32.to_le_bytes());
    f.extend(record(0x04, &channel));
    for c in chunks {
        f.extend(c);
    }
    f.extend(record(0x0f, &0u32.to_le_bytes()));
    f.extend(record(0x02, &[0u8; 20]));
    f.extend_from_slice(MAGIC);
    f
}

/// `n` chunks, each `size` bytes of zeros compressed, each declaring `declared` bytes.
fn bomb(n: usize, size: usize, declared: u64, compression: Compression) -> Vec<u8> {
    let compressed = compression.compress(&zero_message(size));
    mcap_file((0..n).map(|_| chunk(&compressed, declared, compression)))
}

fn expands_too_much(e: &RecordingError, len: usize) -> bool {
    let limits = ReadLimits::default();
    matches!(e, RecordingError::DecompressesTooMuch { input_len, ratio, limit, .. }
        if *input_len == len as u64
            && *ratio == limits.max_expansion
            && *limit == limits.decompressed_limit(len as u64))
        && e.to_string().contains(&format!(
            "decompresses to more than {}x its size",
            limits.max_expansion
        ))
}

#[test]
fn a_34_kb_file_of_zstd_zeros_that_claims_a_gib_is_refused_naming_the_ratio() {
    // 16 chunks of 64 MiB, each under the 64 MiB record limit: it peaked at 1 GiB resident.
    for compression in [Compression::Zstd, Compression::ZstdStream, Compression::Lz4] {
        let n = if matches!(compression, Compression::Lz4) {
            4
        } else {
            16
        };
        let bytes = bomb(n, 64 * MIB, 64 * MIB as u64, compression);
        let e = read_session_bytes(&bytes, &ReadLimits::default()).unwrap_err();
        assert!(expands_too_much(&e, bytes.len()), "{compression:?}: {e}");
        // The session reader (uploads, `icms segment`) streams: it refuses the first problem
        // in file order, the ratio or, where the first chunk is within it (lz4's 4 chunks),
        // that chunk's content, before the chunk that crosses the ratio is decompressed.
        let e = services::session::read_session_bytes(&bytes, "bomb", &ReadLimits::default())
            .unwrap_err();
        assert!(
            expands_too_much(&e, bytes.len())
                || matches!(&e, RecordingError::InvalidJson { index: 0, .. }),
            "{compression:?}: {e}"
        );
    }
}

#[test]
fn many_chunks_each_under_the_record_limit_are_refused_when_together_they_pass_the_ratio() {
    for compression in [Compression::Zstd, Compression::Lz4] {
        let bytes = bomb(400, MIB, MIB as u64, compression);
        let e = read_session_bytes(&bytes, &ReadLimits::default()).unwrap_err();
        assert!(expands_too_much(&e, bytes.len()), "{compression:?}: {e}");
        let RecordingError::DecompressesTooMuch { total, limit, .. } = e else {
            unreachable!()
        };
        // Refused at the chunk that crosses the limit.
        assert!(
            total > limit && total - limit <= MIB as u64,
            "{total} {limit}"
        );
    }
}

#[test]
fn a_chunk_whose_header_declares_less_than_it_holds_is_refused_at_the_declared_size() {
    // 64 MiB of zeros behind a header that declares 1 MiB: within the budget of a small file,
    // so it is decompressed, but never past the 1 MiB declared.
    for compression in [Compression::Zstd, Compression::ZstdStream, Compression::Lz4] {
        let bytes = bomb(1, 64 * MIB, MIB as u64, compression);
        let e = read_session_bytes(&bytes, &ReadLimits::default()).unwrap_err();
        let text = e.to_string();
        assert!(
            matches!(e, RecordingError::Corrupt { .. })
                && text.contains(
                    "chunk decompresses to more than the 1048576 bytes its header declares"
                ),
            "{compression:?}: {text}"
        );
    }
    // A header that declares more than the chunk holds counts against the budget as declared,
    // and is refused as corrupt when the content comes up short.
    let compressed = Compression::Zstd.compress(&zero_message(1000));
    let bytes = mcap_file([chunk(&compressed, 2000, Compression::Zstd)]);
    let e = read_session_bytes(&bytes, &ReadLimits::default()).unwrap_err();
    assert!(
        e.to_string()
            .contains("chunk content is 1000 bytes, its header says 2000"),
        "{e}"
    );
    let bytes = mcap_file([chunk(&compressed, 1 << 40, Compression::Zstd)]);
    let e = read_session_bytes(&bytes, &ReadLimits::default()).unwrap_err();
    assert!(expands_too_much(&e, bytes.len()), "{e}");
}

#[test]
fn a_file_of_tiny_messages_is_refused_when_their_index_would_pass_the_limit() {
    // 40 bytes of index for each 33-byte message: the data alone is within the budget.
    let bytes = tiny_message_file();
    let limit = ReadLimits::default().decompressed_limit(bytes.len() as u64);
    assert!(60 * MIB as u64 <= limit, "{limit}");
    let e = read_session_bytes(&bytes, &ReadLimits::default()).unwrap_err();
    assert!(expands_too_much(&e, bytes.len()), "{e}");
    assert!(e.to_string().contains("decompressed and indexed"), "{e}");
}

#[test]
fn the_limit_is_the_ratio_times_the_length_plus_an_allowance_capped_absolutely() {
    let limits = ReadLimits::default();
    assert_eq!(limits.max_expansion, 128);
    assert_eq!(limits.decompressed_limit(0), MIB as u64);
    assert_eq!(limits.decompressed_limit(1000), 128_000 + MIB as u64);
    assert_eq!(
        limits.decompressed_limit(1 << 40),
        limits.max_total_message_bytes
    );
    assert_eq!(limits.max_total_message_bytes, 4 << 30);
    // Past the absolute cap the error names it instead of the ratio.
    let small = ReadLimits {
        max_total_message_bytes: 2 * MIB as u64,
        expansion_allowance: 1 << 30,
        ..ReadLimits::default()
    };
    let bytes = bomb(4, MIB, MIB as u64, Compression::Zstd);
    let e = read_session_bytes(&bytes, &small).unwrap_err();
    assert!(
        matches!(e, RecordingError::TooMuchData { limit } if limit == 2 * MIB as u64),
        "{e}"
    );
}

#[test]
fn the_ratio_applies_to_files_read_from_disk_whatever_limits_the_caller_passes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bomb.mcap");
    let bytes = bomb(16, 64 * MIB, 64 * MIB as u64, Compression::Zstd);
    std::fs::write(&path, &bytes).unwrap();
    let e = read_session_file(&path, &ReadLimits::default()).unwrap_err();
    assert!(expands_too_much(&e, bytes.len()), "{e}");
    let e = services::session::read_session(&path).unwrap_err();
    assert!(expands_too_much(&e, bytes.len()), "{e}");
    // A stricter ratio refuses an ordinary file that expands 5x.
    let ordinary = mcap_ordinary_file(&dir.path().join("ordinary.mcap"));
    read_session_file(&ordinary, &ReadLimits::default()).unwrap();
    let strict = ReadLimits {
        max_expansion: 2,
        expansion_allowance: 0,
        ..ReadLimits::default()
    };
    let e = read_session_file(&ordinary, &strict).unwrap_err();
    assert!(
        e.to_string()
            .contains("decompresses to more than 2x its size"),
        "{e}"
    );
}

/// A file of the mcap crate's writer: 2 000 messages of JSON text that compress about 5x.
fn mcap_ordinary_file(path: &Path) -> std::path::PathBuf {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .create(&mut out)
        .unwrap();
    let channel = w
        .add_channel(0, "/numbers", "json", &Default::default())
        .unwrap();
    let mut x = 0x2545_f491_4f6c_dd1du64;
    for i in 0..2000u64 {
        let values: Vec<String> = (0..20)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                format!("{:.3}", (x % 10_000) as f64 * 1e-3)
            })
            .collect();
        let data = format!("{{\"values\":[{}]}}", values.join(","));
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: i as u32,
                log_time: i * 1_000_000,
                publish_time: i * 1_000_000,
            },
            data.as_bytes(),
        )
        .unwrap();
    }
    w.finish().unwrap();
    drop(w);
    out.flush().unwrap();
    path.to_path_buf()
}

#[test]
fn a_valid_mcap_of_zero_payloads_written_by_the_mcap_library_is_refused() {
    // Not hand-made: the mcap crate's own writer, zstd chunks of 4 MiB, 256 MiB of messages.
    let mut out = std::io::Cursor::new(Vec::new());
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .chunk_size(Some(4 << 20))
        .create(&mut out)
        .unwrap();
    let channel = w
        .add_channel(0, "/zeros", "json", &Default::default())
        .unwrap();
    let payload = vec![b' '; MIB];
    for i in 0..256u64 {
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: i as u32,
                log_time: i,
                publish_time: i,
            },
            &payload,
        )
        .unwrap();
    }
    w.finish().unwrap();
    drop(w);
    let bytes = out.into_inner();
    assert!(bytes.len() < MIB / 4, "{}", bytes.len());
    let e = read_session_bytes(&bytes, &ReadLimits::default()).unwrap_err();
    assert!(expands_too_much(&e, bytes.len()), "{e}");
    // Salvage reads with the same budget: it keeps nothing past it, and says why.
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("in.mcap"), dir.path().join("out.mcap"));
    std::fs::write(&input, &bytes).unwrap();
    match salvage(&input, &output) {
        Ok(report) => {
            let reason = report.stop_reason.unwrap_or_default();
            assert!(
                reason.contains("decompresses to more than 128x"),
                "{reason}"
            );
            let salvaged = std::fs::metadata(&output).unwrap().len();
            assert!(salvaged < 2 * ReadLimits::default().decompressed_limit(bytes.len() as u64));
        }
        Err(e) => assert!(
            e.to_string().contains("decompresses to more than 128x"),
            "{e}"
        ),
    }
}

// --- Memory: the peak resident set of a child process reading a bomb. ---------------------

/// Environment variable naming the file the child reads.
const CHILD_FILE: &str = "ICMS_BOMB_TEST_FILE";

/// Peak resident set of this process (kB), from `/proc/self/status`.
fn peak_rss_kb() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status")
        .expect("/proc/self/status: these memory tests need Linux");
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmHWM in /proc/self/status")
}

/// Not a test of its own: the child process of [`peak_memory_of_reading`]. Reads the file
/// named by [`CHILD_FILE`] as an upload is read (`ingest::analyse`) and prints its peak
/// resident set before and after.
#[test]
#[ignore = "the child process of the memory tests"]
fn child_process_reads_the_file_named_by_the_environment() {
    let Ok(path) = std::env::var(CHILD_FILE) else {
        return;
    };
    let bytes = std::fs::read(path).unwrap();
    let before = peak_rss_kb();
    let result = services::ingest::analyse(&bytes, "bomb");
    let after = peak_rss_kb();
    let outcome = match result {
        Ok(_) => "ok".to_owned(),
        Err(e) => e.to_string(),
    };
    println!("\nPEAK_RSS_KB {before} {after} {outcome}");
}

/// Reads `bytes` in a child process; its peak resident set while reading (kB) and the
/// outcome.
fn peak_memory_of_reading(bytes: &[u8]) -> (u64, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bomb.mcap");
    std::fs::write(&path, bytes).unwrap();
    let out = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "decompression_bombs::child_process_reads_the_file_named_by_the_environment",
            "--ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_FILE, &path)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout
        .lines()
        .find_map(|l| l.split_once("PEAK_RSS_KB ").map(|(_, rest)| rest))
        .unwrap_or_else(|| panic!("no PEAK_RSS_KB from the child: {stdout}"));
    let mut parts = line.splitn(3, ' ');
    let before: u64 = parts.next().unwrap().parse().unwrap();
    let after: u64 = parts.next().unwrap().parse().unwrap();
    (
        after.saturating_sub(before),
        parts.next().unwrap_or("").to_owned(),
    )
}

#[test]
fn reading_a_bomb_holds_no_more_memory_than_the_limit_of_its_size() {
    let limits = ReadLimits::default();
    for (what, bytes) in [
        (
            "16 zstd chunks of 64 MiB",
            bomb(16, 64 * MIB, 64 * MIB as u64, Compression::Zstd),
        ),
        (
            "400 lz4 chunks of 1 MiB",
            bomb(400, MIB, MIB as u64, Compression::Lz4),
        ),
        (
            "a zstd chunk of 64 MiB declaring 1 MiB",
            bomb(1, 64 * MIB, MIB as u64, Compression::ZstdStream),
        ),
        ("1.9 million tiny messages", tiny_message_file()),
        // Just under the limit: 64 lz4 chunks of 1 MiB and a private record of padding that
        // makes the file long enough for them; every chunk is decompressed and held, then the
        // file is refused (no session topics).
        ("64 MiB of lz4 chunks just under the limit", {
            let compressed = Compression::Lz4.compress(&zero_message(MIB));
            let padding = record(0x80, &vec![0u8; MIB / 2]);
            let chunks = (0..64).map(|_| chunk(&compressed, MIB as u64, Compression::Lz4));
            let bytes = mcap_file(std::iter::once(padding).chain(chunks));
            assert!(limits.decompressed_limit(bytes.len() as u64) >= 64 * MIB as u64);
            bytes
        }),
    ] {
        let (peak_kb, outcome) = peak_memory_of_reading(&bytes);
        let n = bytes.len() as u64;
        // The decompressed data, the compressed copies, and room for the reader's threads
        // and codecs.
        let bound = limits.decompressed_limit(n) + 3 * n + 16 * MIB as u64;
        assert!(
            peak_kb * 1024 <= bound,
            "{what}: {n} bytes peaked at {peak_kb} kB, over {} kB ({outcome})",
            bound / 1024
        );
        assert!(outcome != "ok", "{what}");
        eprintln!("{what}: {n} bytes, peak +{peak_kb} kB: {outcome}");
    }
}

#[test]
fn a_record_inside_a_chunk_whose_string_claims_gigabytes_is_refused_by_the_reader_and_salvage() {
    // A channel record in a chunk whose topic declares 3 GiB: the mcap crate would allocate
    // the declared length before reading it (found by `icms-fuzz session` in salvage,
    // `fuzz/findings/session-salvage-chunked-channel-3gib.bin`).
    let mut channel = Vec::new();
    channel.extend_from_slice(&2u16.to_le_bytes());
    channel.extend_from_slice(&0u16.to_le_bytes());
    channel.extend_from_slice(&(3u32 << 30).to_le_bytes());
    channel.extend_from_slice(b"/topic");
    let content = record(0x04, &channel);
    let bytes = mcap_file([chunk(
        &Compression::Zstd.compress(&content),
        content.len() as u64,
        Compression::Zstd,
    )]);
    let e = read_session_bytes(&bytes, &ReadLimits::default()).unwrap_err();
    assert!(
        e.to_string()
            .contains("channel topic declares 3221225472 bytes"),
        "{e}"
    );
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.mcap");
    std::fs::write(&input, &bytes).unwrap();
    // Salvage recovers nothing from it (an error) or stops at it (a report), naming the field.
    let why = |input: &Path, out: &str| match salvage(input, dir.path().join(out)) {
        Ok(report) => report.stop_reason.unwrap_or_default(),
        Err(e) => e.to_string(),
    };
    let w = why(&input, "out.mcap");
    assert!(w.contains("channel topic declares 3221225472 bytes"), "{w}");
    // The saved finding itself is refused the same way.
    let finding = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/findings/session-salvage-chunked-channel-3gib.bin");
    let w = why(&finding, "finding.mcap");
    assert!(
        w.contains("declares") && w.contains("bytes but the record holds"),
        "{w}"
    );
}
