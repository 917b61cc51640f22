//! The bounds on a URDF text checked before it is parsed: its size and element nesting.

use super::{MAX_URDF_BYTES, MAX_URDF_DEPTH};
use crate::error::{DfsError, Result};

/// Checks a URDF text's size ([`MAX_URDF_BYTES`]) and element nesting ([`MAX_URDF_DEPTH`])
/// before it is parsed, in one pass over the bytes with no recursion. The scan follows the
/// XML tokenizer of `urdf-rs` (RustyXML): comments end at the first `-->`, CDATA at the first
/// `]]>`, processing instructions at the first `>` after a `?`, a `<!DOCTYPE` and an end tag at
/// their first `>`, and a start tag at its first `>` outside an attribute value (a value is
/// quoted after `=`); a start tag ending `/>` is empty. Where it may end a construct earlier
/// than that parser, it only counts more depth. A malformed text within the bounds is left
/// to the parser to report.
pub fn check_urdf_text(urdf: &str) -> Result<()> {
    if urdf.len() > MAX_URDF_BYTES {
        return Err(DfsError::invalid(
            "urdf",
            format!(
                "the URDF is {} bytes; at most {MAX_URDF_BYTES} ({} MiB) are accepted",
                urdf.len(),
                MAX_URDF_BYTES >> 20
            ),
        ));
    }
    let deepest = nesting_depth(urdf.as_bytes());
    if deepest > MAX_URDF_DEPTH {
        return Err(DfsError::invalid(
            "urdf",
            format!(
                "the URDF nests elements {deepest} deep; at most {MAX_URDF_DEPTH} are accepted"
            ),
        ));
    }
    Ok(())
}

/// The deepest element nesting of an XML text, scanned as [`check_urdf_text`] describes.
pub(super) fn nesting_depth(b: &[u8]) -> usize {
    // Index of the first occurrence of `pat` at or after `from` (the end when there is none).
    let find = |from: usize, pat: &[u8]| -> usize {
        b.get(from..)
            .and_then(|rest| rest.windows(pat.len()).position(|w| w == pat))
            .map_or(b.len(), |p| from + p)
    };
    let mut depth = 0usize;
    // The deepest nesting, reported whole when it is over the limit.
    let mut deepest = 0usize;
    let mut i = 0;
    while i < b.len() {
        if b[i] != b'<' {
            i += 1;
            continue;
        }
        let rest = &b[i..];
        if rest.starts_with(b"<!--") {
            i = find(i + 4, b"-->") + 3;
        } else if rest.starts_with(b"<![CDATA[") {
            i = find(i + 9, b"]]>") + 3;
        } else if rest.starts_with(b"<?") {
            let q = find(i + 2, b"?");
            i = find(q, b">") + 1;
        } else if rest.starts_with(b"<!") || rest.starts_with(b"</") {
            if rest.starts_with(b"</") {
                depth = depth.saturating_sub(1);
            }
            i = find(i + 2, b">") + 1;
        } else {
            // A start tag: its name, then attributes `name = "value"`, until `>` or `/>`.
            depth += 1;
            deepest = deepest.max(depth);
            let (end, empty) = start_tag_end(b, i + 1);
            if empty {
                depth -= 1;
            }
            i = end + 1;
        }
    }
    deepest
}

/// Where the start tag whose name begins at `from` ends (the index of its `>`, or the text's
/// end) and whether it is empty (`/>`): the states of RustyXML's tokenizer, in which a quote
/// opens an attribute value only after an attribute name and `=`.
fn start_tag_end(b: &[u8], from: usize) -> (usize, bool) {
    #[derive(PartialEq)]
    enum State {
        Name,
        InTag,
        AttrName,
        ExpectValue,
    }
    let mut state = State::Name;
    let mut j = from;
    while j < b.len() {
        let c = b[j];
        match (&state, c) {
            (State::Name | State::InTag, b'>') => return (j, false),
            (State::Name | State::InTag, b'/') if b.get(j + 1) == Some(&b'>') => {
                return (j + 1, true)
            }
            (State::Name, c) if c.is_ascii_whitespace() => state = State::InTag,
            (State::InTag, c) if !c.is_ascii_whitespace() && c != b'/' => state = State::AttrName,
            (State::AttrName, b'=') => state = State::ExpectValue,
            (State::ExpectValue, b'"' | b'\'') => {
                // The value runs to the same quote.
                j = b[j + 1..]
                    .iter()
                    .position(|&q| q == c)
                    .map_or(b.len(), |p| j + 1 + p);
                state = State::InTag;
            }
            (State::ExpectValue, c) if !c.is_ascii_whitespace() => {
                // Malformed (the parser refuses it): read on as a tag.
                state = State::InTag;
                continue;
            }
            (State::AttrName, b'>') => return (j, false),
            _ => {}
        }
        j += 1;
    }
    (b.len(), false)
}
