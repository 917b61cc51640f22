//! A zstd chunk decompressor whose window is capped, so a crafted frame header cannot make the
//! decoder allocate more than [`MAX_WINDOW_LOG`] bytes (zstd's own default cap is 128 MiB).
//!
//! Same behaviour as the `mcap` crate's built-in decoder otherwise.

use mcap::sans_io::decompressor::{DecompressResult, Decompressor};
use mcap::{McapError, McapResult};
use zstd::zstd_safe::{get_error_name, DParameter, DStream, InBuffer, OutBuffer, ResetDirective};

/// log2 of the largest zstd window accepted: 16 MiB. Our writer's chunks are 1 MiB (zstd level 3
/// uses a 2 MiB window at most); other writers' defaults stay well below this too.
pub(crate) const MAX_WINDOW_LOG: u32 = 24;

#[derive(Default)]
pub(crate) struct BoundedZstd {
    stream: Option<DStream<'static>>,
    need: usize,
}

fn check(res: zstd::zstd_safe::SafeResult) -> McapResult<usize> {
    res.map_err(|code| McapError::DecompressionError(get_error_name(code).into()))
}

impl BoundedZstd {
    fn stream(&mut self) -> McapResult<&mut DStream<'static>> {
        if self.stream.is_none() {
            let mut stream = DStream::create();
            check(stream.init())?;
            check(stream.set_parameter(DParameter::WindowLogMax(MAX_WINDOW_LOG)))?;
            self.stream = Some(stream);
        }
        Ok(self.stream.as_mut().expect("stream was just created"))
    }
}

impl Decompressor for BoundedZstd {
    fn next_read_size(&self) -> usize {
        self.need
    }

    fn decompress(&mut self, src: &[u8], dst: &mut [u8]) -> McapResult<DecompressResult> {
        let stream = self.stream()?;
        let mut input = InBuffer::around(src);
        let mut output = OutBuffer::around(dst);
        self.need = check(stream.decompress_stream(&mut output, &mut input))?;
        Ok(DecompressResult {
            consumed: input.pos,
            wrote: output.pos(),
        })
    }

    fn reset(&mut self) -> McapResult<()> {
        self.need = 0;
        if let Some(stream) = self.stream.as_mut() {
            // Parameters (the window cap) survive a session-only reset.
            check(stream.reset(ResetDirective::SessionOnly))?;
        }
        Ok(())
    }

    fn name(&self) -> &'static str {
        "zstd"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip(window_log: u32) -> McapResult<Vec<u8>> {
        let data: Vec<u8> = (0..200_000u32)
            .flat_map(|i| (i % 251).to_le_bytes())
            .collect();
        let mut enc = zstd::zstd_safe::CCtx::create();
        enc.set_parameter(zstd::zstd_safe::CParameter::WindowLog(window_log))
            .unwrap();
        let mut compressed = vec![0u8; zstd::zstd_safe::compress_bound(data.len())];
        let n = enc.compress2(&mut compressed[..], &data).unwrap();
        compressed.truncate(n);
        let mut dec = BoundedZstd::default();
        let mut out = vec![0u8; data.len()];
        let mut consumed = 0;
        let mut wrote = 0;
        while wrote < out.len() {
            let r = dec.decompress(&compressed[consumed..], &mut out[wrote..])?;
            if r.consumed == 0 && r.wrote == 0 {
                break;
            }
            consumed += r.consumed;
            wrote += r.wrote;
        }
        assert_eq!(out, data);
        Ok(out)
    }

    #[test]
    fn frames_within_the_window_cap_decode() {
        roundtrip(20).unwrap();
    }

    #[test]
    fn a_frame_declaring_a_1_gib_window_is_refused_before_allocating_it() {
        // Magic, descriptor (no content size, not single-segment), window 2^30, then one raw
        // last block holding one byte.
        let frame = [
            0x28,
            0xb5,
            0x2f,
            0xfd,
            0x00,
            20 << 3,
            0x09,
            0x00,
            0x00,
            b'x',
        ];
        let mut dec = BoundedZstd::default();
        let mut out = [0u8; 16];
        let err = dec.decompress(&frame, &mut out).unwrap_err();
        assert!(matches!(err, McapError::DecompressionError(_)), "{err:?}");
        // The same frame with a 64 kB window decodes.
        let mut ok = frame;
        ok[5] = 6 << 3;
        let mut dec = BoundedZstd::default();
        let r = dec.decompress(&ok, &mut out).unwrap();
        assert_eq!(&out[..r.wrote], b"x");
    }
}
