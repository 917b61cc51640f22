//! URDF-aware text mutation: tags duplicated or deleted, attribute values replaced with
//! interesting numbers, other names (kinematic loops, unknown links) or long strings, whole
//! `<link>` / `<joint>` blocks duplicated or spliced from another hand, joint types changed,
//! deep nesting, entities and DOCTYPEs, truncation.

use crate::bytes;
use crate::rng::Rng;

/// Spans `[start, end)` of every `<...>` tag.
fn tags(t: &str) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let b = t.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'<' {
            if let Some(j) = t[i..].find('>') {
                out.push((i, i + j + 1));
                i += j + 1;
                continue;
            }
        }
        i += 1;
    }
    out
}

/// Spans of attribute values (inside the quotes).
fn values(t: &str) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while let Some(j) = t[i..].find("=\"") {
        let s = i + j + 2;
        match t[s..].find('"') {
            Some(k) => {
                out.push((s, s + k));
                i = s + k + 1;
            }
            None => break,
        }
    }
    out
}

/// Spans of whole `<name ...>...</name>` (or self-closed) elements.
fn blocks(t: &str, name: &str) -> Vec<(usize, usize)> {
    let open = format!("<{name}");
    let close = format!("</{name}>");
    let mut out = Vec::new();
    let mut i = 0;
    while let Some(j) = t[i..].find(&open) {
        let s = i + j;
        let Some(gt) = t[s..].find('>') else { break };
        let end = if t[s..s + gt].ends_with('/') {
            s + gt + 1
        } else {
            match t[s..].find(&close) {
                Some(c) => s + c + close.len(),
                None => break,
            }
        };
        out.push((s, end));
        i = end;
    }
    out
}

/// Char-boundary-safe position at or before `i`.
fn floor(t: &str, mut i: usize) -> usize {
    i = i.min(t.len());
    while !t.is_char_boundary(i) {
        i -= 1;
    }
    i
}

const NUMBERS: [&str; 22] = [
    "0",
    "-1",
    "1e308",
    "-1e308",
    "1e309",
    "NaN",
    "inf",
    "-inf",
    "5e-324",
    "0 0 0",
    "NaN NaN NaN",
    "1e308 1e308 1e308",
    "0 0",
    "1 2 3 4",
    "",
    " ",
    "1,2,3",
    "0x10",
    "1e-300 0 0",
    "3.14159 0 0",
    "100000 0 0",
    "-0",
];

const JOINT_TYPES: [&str; 8] = [
    "revolute",
    "continuous",
    "prismatic",
    "fixed",
    "floating",
    "planar",
    "bogus",
    "",
];

/// Largest URDF a mutation leaves (bytes).
pub const MAX_URDF: usize = 8 << 20;

/// One URDF-aware mutation of `t`; `others` are the other hands' URDFs.
pub fn mutate(rng: &mut Rng, t: &mut String, others: &[&str]) {
    mutate_once(rng, t, others);
    if t.len() > MAX_URDF {
        let n = floor(t, MAX_URDF);
        t.truncate(n);
    }
}

/// XML oddities inserted after a tag: entities, DOCTYPEs, CDATA, a second root, broken
/// elements.
const ODDITIES: [&str; 19] = [
    "&lt;",
    "&#xFFFF;",
    "&#0;",
    "&unknown;",
    "<!DOCTYPE r [<!ENTITY a \"aaaaaaaaaa\"><!ENTITY b \"&a;&a;&a;&a;&a;\">]>",
    "<![CDATA[ <joint> ]]>",
    "<!-- -->",
    "<?xml version=\"1.0\"?>",
    "<?pi ?>",
    "\u{0}",
    "\u{feff}",
    "<robot name=\"second\"></robot>",
    "</robot>",
    "<link name=\"\"/>",
    "<joint name=\"j\" type=\"revolute\"><parent link=\"x\"/><child link=\"x\"/></joint>",
    "<mimic joint=\"j\" multiplier=\"1e308\"/>",
    "<limit lower=\"1\" upper=\"-1\" effort=\"-1\" velocity=\"NaN\"/>",
    "<axis xyz=\"0 0 0\"/>",
    "<inertial><mass value=\"-1\"/><inertia ixx=\"NaN\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial>",
];

/// One mutation, before the size bound: a table of mutation kinds weighted by the ranges of
/// `rng.below(14)`, each kind a function of its own below.
fn mutate_once(rng: &mut Rng, t: &mut String, others: &[&str]) {
    match rng.below(14) {
        0 => duplicate_tag(rng, t),
        1 => delete_tag(rng, t),
        2 | 3 => replace_value(rng, t),
        4 => nest_deeply(rng, t),
        5 | 6 => duplicate_block(rng, t, others),
        7 => delete_block(rng, t),
        8 => change_joint_type(rng, t),
        9 => insert_oddity(rng, t),
        10 => rename(rng, t),
        11 => {
            let n = floor(t, rng.below(t.len() + 1));
            t.truncate(n);
        }
        _ => mutate_bytes(rng, t),
    }
}

/// Copies a tag before another one.
fn duplicate_tag(rng: &mut Rng, t: &mut String) {
    let tg = tags(t);
    if tg.is_empty() {
        return;
    }
    let (s, e) = *rng.pick(&tg);
    let piece = t[s..e].to_owned();
    let (at, _) = *rng.pick(&tg);
    t.insert_str(at, &piece);
}

/// Deletes a tag.
fn delete_tag(rng: &mut Rng, t: &mut String) {
    let tg = tags(t);
    if tg.is_empty() {
        return;
    }
    let (s, e) = *rng.pick(&tg);
    t.replace_range(s..e, "");
}

/// An attribute value: a number, another value (names: loops, unknown links), long.
fn replace_value(rng: &mut Rng, t: &mut String) {
    let vs = values(t);
    if vs.is_empty() {
        return;
    }
    let (s, e) = *rng.pick(&vs);
    let new = match rng.below(4) {
        0 | 1 => (*rng.pick(&NUMBERS)).to_owned(),
        2 => {
            let (s2, e2) = *rng.pick(&vs);
            t[s2..e2].to_owned()
        }
        _ => "n".repeat(rng.small_size(100_000)),
    };
    t.replace_range(s..e, &new);
}

/// Nests an unknown element deeply.
fn nest_deeply(rng: &mut Rng, t: &mut String) {
    let depth = if rng.one_in(3) {
        rng.range(1000, 20_000)
    } else {
        rng.small_size(500)
    };
    let tg = tags(t);
    let at = tg.get(1).map_or(0, |x| x.0);
    let mut ins = "<a>".repeat(depth);
    if !rng.one_in(4) {
        ins.push_str(&"</a>".repeat(depth));
    }
    t.insert_str(at, &ins);
}

/// Duplicates a link or joint (same names twice), or splices one from another hand.
fn duplicate_block(rng: &mut Rng, t: &mut String, others: &[&str]) {
    let name = if rng.one_in(2) { "link" } else { "joint" };
    let src: &str = if !others.is_empty() && rng.one_in(3) {
        others[rng.below(others.len())]
    } else {
        t
    };
    let bs = blocks(src, name);
    if bs.is_empty() {
        return;
    }
    let (s, e) = *rng.pick(&bs);
    let piece = src[s..e].to_owned();
    let own = blocks(t, name);
    let at = own.get(rng.below(own.len().max(1))).map_or(0, |x| x.1);
    t.insert_str(floor(t, at), &piece);
}

/// Deletes a whole link or joint.
fn delete_block(rng: &mut Rng, t: &mut String) {
    let name = if rng.one_in(2) { "link" } else { "joint" };
    let bs = blocks(t, name);
    if bs.is_empty() {
        return;
    }
    let (s, e) = *rng.pick(&bs);
    t.replace_range(s..e, "");
}

/// A joint type.
fn change_joint_type(rng: &mut Rng, t: &mut String) {
    let at: Vec<usize> = t.match_indices("type=\"").map(|(i, _)| i + 6).collect();
    if at.is_empty() {
        return;
    }
    let s = *rng.pick(&at);
    if let Some(e) = t[s..].find('"') {
        let new = *rng.pick(&JOINT_TYPES);
        t.replace_range(s..s + e, new);
    }
}

/// Inserts one of the [`ODDITIES`] after a tag.
fn insert_oddity(rng: &mut Rng, t: &mut String) {
    let ins = *rng.pick(&ODDITIES);
    let tg = tags(t);
    let at = if tg.is_empty() { 0 } else { rng.pick(&tg).1 };
    t.insert_str(at, ins);
}

/// Renames a name attribute (unknown fingertip links, broken parents).
fn rename(rng: &mut Rng, t: &mut String) {
    let at: Vec<usize> = t.match_indices("name=\"").map(|(i, _)| i + 6).collect();
    if at.is_empty() {
        return;
    }
    let s = *rng.pick(&at);
    t.insert(s, 'x');
}

/// Mutates the text's bytes (invalid UTF-8 is replaced).
fn mutate_bytes(rng: &mut Rng, t: &mut String) {
    let mut b = std::mem::take(t).into_bytes();
    let n = rng.range(1, 3);
    bytes::mutate_n(rng, &mut b, &[], n);
    *t = String::from_utf8_lossy(&b).into_owned();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_blocks_and_values() {
        let t = r#"<robot name="r"><link name="a"/><joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint><link name="b"></link></robot>"#;
        assert_eq!(blocks(t, "link").len(), 2);
        assert_eq!(blocks(t, "joint").len(), 1);
        assert_eq!(values(t).len(), 7);
        for i in 0..300 {
            let mut rng = Rng::for_input("xml", 0, i);
            let mut s = t.to_owned();
            mutate(&mut rng, &mut s, &[t]);
        }
    }
}
