//! zstd decoding with a capped window, so a crafted frame header cannot make the decoder
//! allocate more than 2^[`MAX_WINDOW_LOG`] bytes (zstd's own default cap is 128 MiB). The one
//! way the crate decodes zstd: every context comes from [`bounded_dctx`], used as a streaming
//! decompressor for the `mcap` crate's reader ([`BoundedZstd`], otherwise the same as its
//! built-in one) and single-pass into a buffer of a chunk's declared size by the reader's own
//! chunk decoding (`reader/chunk.rs`).

use mcap::sans_io::decompressor::{DecompressResult, Decompressor};
use mcap::{McapError, McapResult};
use zstd::zstd_safe::{get_error_name, DCtx, DParameter, InBuffer, OutBuffer, ResetDirective};

/// log2 of the largest zstd window accepted: 16 MiB. Our writer's chunks are 1 MiB (zstd level 3
/// uses a 2 MiB window at most); other writers' defaults stay well below this too.
pub(crate) const MAX_WINDOW_LOG: u32 = 24;

/// The window-capped decompression context in `slot`, made there on first use (the cap is a
/// sticky parameter: it survives the session resets between frames, so a context is made once
/// and reused); the error is zstd's name for what failed.
pub(crate) fn bounded_dctx<'a>(
    slot: &'a mut Option<DCtx<'static>>,
) -> Result<&'a mut DCtx<'static>, &'static str> {
    match slot {
        Some(d) => Ok(d),
        None => {
            let mut d = DCtx::create();
            d.set_parameter(DParameter::WindowLogMax(MAX_WINDOW_LOG))
                .map_err(get_error_name)?;
            Ok(slot.insert(d))
        }
    }
}

/// A streaming zstd decompressor for the `mcap` crate's reader, with the window cap of
/// [`bounded_dctx`].
#[derive(Default)]
pub(crate) struct BoundedZstd {
    stream: Option<DCtx<'static>>,
    need: usize,
}

fn check(res: zstd::zstd_safe::SafeResult) -> McapResult<usize> {
    res.map_err(|code| McapError::DecompressionError(get_error_name(code).into()))
}

impl Decompressor for BoundedZstd {
    fn next_read_size(&self) -> usize {
        self.need
    }

    fn decompress(&mut self, src: &[u8], dst: &mut [u8]) -> McapResult<DecompressResult> {
        // A fresh context decodes a stream as it is (no `init` needed since zstd 1.4).
        let stream = bounded_dctx(&mut self.stream)
            .map_err(|name| McapError::DecompressionError(name.into()))?;
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
