//! Byte-level mutations: flips, random bytes, insertion, deletion, duplication, splicing,
//! truncation and interesting integers.

use crate::rng::Rng;

/// Largest input a byte mutation grows to (bytes).
pub const MAX_LEN: usize = 8 << 20;

/// Interesting integers, written in little-endian at a random offset.
const INTERESTING: [u64; 16] = [
    0,
    1,
    0x7f,
    0x80,
    0xff,
    0x7fff,
    0x8000,
    0xffff,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_ffff,
    0x1_0000_0000,
    0x7fff_ffff_ffff_ffff,
    0x8000_0000_0000_0000,
    u64::MAX,
    u64::MAX - 1,
];

/// Interesting texts for numbers and strings inside text formats.
pub const INTERESTING_TEXT: [&str; 24] = [
    "0",
    "-0",
    "-1",
    "1",
    "2147483648",
    "-2147483649",
    "4294967296",
    "9223372036854775808",
    "18446744073709551616",
    "-9223372036854775809",
    "1e308",
    "-1e308",
    "1e309",
    "5e-324",
    "1e-400",
    "NaN",
    "nan",
    "Infinity",
    "-inf",
    "0.1e",
    "1.7976931348623157e308",
    "",
    "\u{0}",
    "\u{feff}",
];

/// One random byte-level mutation of `data`; `other` is a second input to splice from.
pub fn mutate(rng: &mut Rng, data: &mut Vec<u8>, other: &[u8]) {
    if data.is_empty() {
        let n = rng.small_size(64);
        data.extend((0..n).map(|_| rng.byte()));
        return;
    }
    match rng.below(12) {
        0 => {
            // Flip one bit.
            let i = rng.below(data.len());
            data[i] ^= 1 << rng.below(8);
        }
        1 => {
            // Random bytes over a short range.
            let i = rng.below(data.len());
            let n = rng.small_size(16).min(data.len() - i);
            for b in &mut data[i..i + n] {
                *b = rng.byte();
            }
        }
        2 => {
            // Insert random bytes.
            let i = rng.below(data.len() + 1);
            let n = rng.small_size(256);
            let ins: Vec<u8> = (0..n).map(|_| rng.byte()).collect();
            data.splice(i..i, ins);
        }
        3 => {
            // Delete a range.
            let i = rng.below(data.len());
            let n = rng.small_size(data.len() - i);
            data.drain(i..i + n);
        }
        4 => {
            // Duplicate a range (possibly many times).
            let i = rng.below(data.len());
            let n = rng.small_size(data.len() - i);
            let times = if rng.one_in(8) { rng.range(2, 64) } else { 1 };
            let piece = data[i..i + n].to_vec();
            let at = rng.below(data.len() + 1);
            let mut ins = Vec::new();
            for _ in 0..times {
                if data.len() + ins.len() + piece.len() > MAX_LEN {
                    break;
                }
                ins.extend_from_slice(&piece);
            }
            data.splice(at..at, ins);
        }
        5 => {
            // Copy a range over another place.
            let i = rng.below(data.len());
            let n = rng.small_size(data.len() - i);
            let j = rng.below(data.len());
            let piece = data[i..i + n].to_vec();
            let m = piece.len().min(data.len() - j);
            data[j..j + m].copy_from_slice(&piece[..m]);
        }
        6 => {
            // Truncate.
            let n = rng.below(data.len());
            data.truncate(n);
        }
        7 if !other.is_empty() => {
            // Splice: our head, the other's tail.
            let i = rng.below(data.len() + 1);
            let j = rng.below(other.len());
            data.truncate(i);
            data.extend_from_slice(&other[j..]);
        }
        8 | 9 => {
            // An interesting integer, 1 to 8 bytes wide.
            let v = *rng.pick(&INTERESTING);
            let width = *rng.pick(&[1usize, 2, 4, 8]);
            let i = rng.below(data.len());
            let bytes = v.to_le_bytes();
            let m = width.min(data.len() - i);
            data[i..i + m].copy_from_slice(&bytes[..m]);
        }
        10 => {
            // Add or subtract a little from a byte.
            let i = rng.below(data.len());
            let d = rng.range(1, 35) as u8;
            data[i] = if rng.one_in(2) {
                data[i].wrapping_add(d)
            } else {
                data[i].wrapping_sub(d)
            };
        }
        _ => {
            // Insert an interesting text.
            let i = rng.below(data.len() + 1);
            let t = rng.pick(&INTERESTING_TEXT).as_bytes().to_vec();
            data.splice(i..i, t);
        }
    }
    data.truncate(MAX_LEN);
}

/// `rounds` byte mutations.
pub fn mutate_n(rng: &mut Rng, data: &mut Vec<u8>, other: &[u8], rounds: usize) {
    for _ in 0..rounds {
        mutate(rng, data, other);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutations_stay_bounded_and_vary() {
        let seed = b"{\"a\": [1, 2, 3], \"b\": \"text\"}".to_vec();
        let mut distinct = std::collections::BTreeSet::new();
        for i in 0..500 {
            let mut rng = Rng::for_input("t", 0, i);
            let mut d = seed.clone();
            mutate_n(&mut rng, &mut d, b"other", 4);
            assert!(d.len() <= MAX_LEN);
            distinct.insert(d);
        }
        assert!(distinct.len() > 400);
    }
}
