//! Structure-aware JSON mutation: the text is parsed into a [`serde_json::Value`], a random
//! node is changed (interesting numbers, a type change, deep nesting, huge arrays, long
//! strings, removed or unknown keys, subtrees from another seed), and the value is written
//! back; some changes are textual because a `Value` cannot hold them (NaN and other
//! non-JSON numbers, a key twice in one object, nesting deeper than serde_json's limit).

use serde_json::{Map, Number, Value};

use crate::bytes;
use crate::rng::Rng;

/// Largest array a mutation builds (elements).
const MAX_ARRAY: usize = 20_000;
/// Largest string a mutation builds (bytes).
const MAX_STRING: usize = 1 << 20;
/// Deepest nesting written as text (serde_json refuses more than 128 by itself).
const MAX_TEXT_DEPTH: usize = 50_000;

/// Interesting numbers a `Value` can hold.
fn interesting_number(rng: &mut Rng) -> Value {
    let f: &[f64] = &[
        0.0,
        -0.0,
        -1.0,
        1.0,
        0.5,
        1e-9,
        -1e-9,
        2147483648.0,
        9.223372036854776e18,
        1.8446744073709552e19,
        1e308,
        -1e308,
        f64::MAX,
        f64::MIN_POSITIVE,
        5e-324,
        1e15,
        3600.0,
        3600.001,
        120.0,
        120.0000001,
        600.0,
        1e-3,
        std::f64::consts::TAU,
        -std::f64::consts::PI,
    ];
    match rng.below(4) {
        0 => Value::from(*rng.pick(&[0i64, -1, 1, 2, 255, 256, 65535, 65536])),
        1 => Value::from(*rng.pick(&[
            i64::MAX,
            i64::MIN,
            i32::MAX as i64,
            i32::MIN as i64,
            (1i64 << 31),
            (1i64 << 32),
            (1i64 << 53) + 1,
            -(1i64 << 53),
        ])),
        2 => Value::from(*rng.pick(&[u64::MAX, 1u64 << 63, (1u64 << 63) + 1])),
        _ => Number::from_f64(*rng.pick(f)).map_or(Value::Null, Value::Number),
    }
}

/// Non-JSON or edge-case number texts, written raw in place of a node.
const RAW_NUMBERS: [&str; 20] = [
    "NaN",
    "Infinity",
    "-Infinity",
    "1e999",
    "-1e999",
    "1e-999",
    "-0",
    "01",
    "1.",
    ".5",
    "+1",
    "0x10",
    "123456789012345678901234567890",
    "-123456789012345678901234567890.5",
    "1e308",
    "18446744073709551616",
    "-9223372036854775809",
    "2e-323",
    "1E+2",
    "4.9406564584124654e-324",
];

/// A random scalar or small container.
fn random_value(rng: &mut Rng) -> Value {
    match rng.below(7) {
        0 => Value::Null,
        1 => Value::Bool(rng.one_in(2)),
        2 => interesting_number(rng),
        3 => Value::String(random_string(rng)),
        4 => Value::Array(Vec::new()),
        5 => Value::Object(Map::new()),
        _ => Value::Array(vec![interesting_number(rng); rng.range(1, 4)]),
    }
}

fn random_string(rng: &mut Rng) -> String {
    match rng.below(6) {
        0 => String::new(),
        1 => (*rng.pick(&bytes::INTERESTING_TEXT)).to_owned(),
        2 => "x".repeat(rng.small_size(100_000)),
        3 => (0..rng.small_size(64))
            .map(|_| char::from_u32(rng.below(0x3000) as u32).unwrap_or('?'))
            .collect(),
        4 => (*rng.pick(&[
            "sphere",
            "box",
            "cylinder",
            "grasp",
            "release",
            "lift",
            "soft_finger",
            "frictionless",
            "point_with_friction",
            "allegro",
            "glove10",
            "gripper",
            "barrett",
            "inspire",
            "thumb",
            "../../etc/passwd",
            "a/b",
            "sphere-lift",
            "two-grasps",
            "pinch",
            "power",
            "auto",
        ]))
        .to_owned(),
        _ => "\u{1F600}é\u{0}\\\"".repeat(rng.small_size(16)),
    }
}

/// JSON pointers of every node (pre-order, at most `limit`).
fn pointers(v: &Value, limit: usize) -> Vec<String> {
    fn walk(v: &Value, path: &mut String, out: &mut Vec<String>, limit: usize) {
        if out.len() >= limit {
            return;
        }
        out.push(path.clone());
        let len = path.len();
        match v {
            Value::Array(a) => {
                for (i, x) in a.iter().enumerate() {
                    path.push('/');
                    path.push_str(&i.to_string());
                    walk(x, path, out, limit);
                    path.truncate(len);
                }
            }
            Value::Object(m) => {
                for (k, x) in m {
                    path.push('/');
                    path.push_str(&k.replace('~', "~0").replace('/', "~1"));
                    walk(x, path, out, limit);
                    path.truncate(len);
                }
            }
            _ => {}
        }
    }
    let mut out = Vec::new();
    walk(v, &mut String::new(), &mut out, limit);
    out
}

/// Raw texts to substitute after serialisation: placeholder string → text.
#[derive(Debug, Default)]
struct Raw {
    items: Vec<(String, String)>,
    /// Duplicate keys: quoted placeholder key (with value `null`) → `"key":value`.
    pairs: Vec<(String, String)>,
}

impl Raw {
    /// A placeholder string value that becomes `text` in the output.
    fn value(&mut self, text: String) -> Value {
        let key = format!("\u{1}FUZZ{}\u{1}", self.items.len());
        self.items.push((key.clone(), text));
        Value::String(key)
    }

    /// Substitutes every placeholder in the serialised text (with `0` where the text would
    /// grow past [`MAX_OUTPUT`]: a raw text copied into a huge array).
    fn apply(&self, mut text: String) -> String {
        // Latest first: a later raw text may contain an earlier placeholder.
        for (key, raw) in self.items.iter().rev() {
            let quoted = serde_json::to_string(key).unwrap_or_default();
            text = bounded_replace(&text, &quoted, raw);
        }
        text
    }
}

/// Largest text a JSON mutation writes (bytes).
pub const MAX_OUTPUT: usize = 16 << 20;

/// `text.replace(from, to)`, or with `0` when the result would be over [`MAX_OUTPUT`].
fn bounded_replace(text: &str, from: &str, to: &str) -> String {
    let n = text.matches(from).count();
    if n == 0 {
        return text.to_owned();
    }
    let grown = text.len() + n.saturating_mul(to.len());
    if grown > MAX_OUTPUT {
        text.replace(from, "0")
    } else {
        text.replace(from, to)
    }
}

/// One structural mutation of `v` (which may be replaced whole).
///
/// One table of mutation kinds, weighted by the ranges of `rng.below(16)`; the kinds longer
/// than a line are functions of their own below.
fn mutate_value(rng: &mut Rng, v: &mut Value, others: &[Value], raw: &mut Raw) {
    let ptrs = pointers(v, 4096);
    let ptr = rng.pick(&ptrs).clone();
    let Some(node) = v.pointer_mut(&ptr) else {
        return;
    };
    match rng.below(16) {
        0 | 1 => *node = interesting_number(rng),
        2 => *node = random_value(rng),
        3 => nest_value(rng, node),
        4 => nest_text(rng, node, raw),
        5 => *node = huge_array(rng, node),
        6 => *node = Value::String(random_string(rng)),
        7 => remove_element(rng, node),
        8 => add_element(rng, node),
        9 => duplicate_key(rng, node, raw),
        10 => *node = raw.value((*rng.pick(&RAW_NUMBERS)).to_owned()),
        11 if !others.is_empty() => splice_subtree(rng, node, others),
        12 => tweak_number(rng, node),
        13 => mutate_string(rng, node),
        14 => copy_other_node(rng, v, &ptrs, &ptr),
        _ => empty_value(node),
    }
}

/// Nests the node a little (serde_json's own limit is 128).
fn nest_value(rng: &mut Rng, node: &mut Value) {
    let depth = rng.small_size(200);
    for _ in 0..depth {
        let inner = std::mem::take(node);
        *node = if rng.one_in(2) {
            Value::Array(vec![inner])
        } else {
            Value::Object(Map::from_iter([("a".to_owned(), inner)]))
        };
    }
}

/// Nests the node far deeper, as text.
fn nest_text(rng: &mut Rng, node: &mut Value, raw: &mut Raw) {
    let depth = if rng.one_in(8) {
        rng.range(100, MAX_TEXT_DEPTH)
    } else {
        rng.range(100, 1000)
    };
    let (open, close) = if rng.one_in(2) {
        ("[", "]")
    } else {
        ("{\"a\":", "}")
    };
    let inner = serde_json::to_string(node).unwrap_or_default();
    let close_all = if rng.one_in(4) {
        String::new()
    } else {
        close.repeat(depth)
    };
    *node = raw.value(format!("{}{inner}{close_all}", open.repeat(depth)));
}

/// A huge array of copies of the node (or of a number).
fn huge_array(rng: &mut Rng, node: &Value) -> Value {
    let elem = if rng.one_in(2) {
        node.clone()
    } else {
        interesting_number(rng)
    };
    let size = serde_json::to_string(&elem).map_or(1, |s| s.len().max(1));
    let n = 1 + rng.small_size((MAX_STRING * 4 / size).clamp(2, MAX_ARRAY));
    Value::Array(vec![elem; n])
}

/// Removes, doubles or truncates at an element of a container; a scalar becomes null.
fn remove_element(rng: &mut Rng, node: &mut Value) {
    match node {
        Value::Array(a) if !a.is_empty() => {
            let i = rng.below(a.len());
            match rng.below(3) {
                0 => {
                    a.remove(i);
                }
                1 => {
                    let x = a[i].clone();
                    a.insert(i, x);
                }
                _ => a.truncate(i),
            }
        }
        Value::Object(m) if !m.is_empty() => {
            let keys: Vec<String> = m.keys().cloned().collect();
            let k = rng.pick(&keys).clone();
            m.remove(&k);
        }
        _ => *node = Value::Null,
    }
}

/// Adds a field or an element to a container; a scalar is wrapped in an array.
fn add_element(rng: &mut Rng, node: &mut Value) {
    match node {
        Value::Object(m) => {
            let k = if rng.one_in(2) {
                random_string(rng)
            } else {
                "unknown_field".to_owned()
            };
            m.insert(k, random_value(rng));
        }
        Value::Array(a) => {
            let x = a.first().cloned().unwrap_or_else(|| random_value(rng));
            a.push(x);
        }
        _ => *node = Value::Array(vec![node.clone()]),
    }
}

/// A key twice in one object (textual: a map cannot hold it); a non-object becomes a raw
/// number.
fn duplicate_key(rng: &mut Rng, node: &mut Value, raw: &mut Raw) {
    if let Value::Object(m) = node {
        if let Some((k, x)) = m.iter().next().map(|(k, x)| (k.clone(), x.clone())) {
            let value = if rng.one_in(2) { x } else { random_value(rng) };
            let text = serde_json::to_string(&value).unwrap_or_default();
            let dup = format!("{}:{text}", serde_json::to_string(&k).unwrap_or_default());
            let placeholder = format!("\u{1}DUP{}\u{1}", raw.pairs.len());
            m.insert(placeholder.clone(), Value::Null);
            let quoted = serde_json::to_string(&placeholder).unwrap_or_default();
            raw.pairs.push((quoted, dup));
        }
    } else {
        *node = raw.value((*rng.pick(&RAW_NUMBERS)).to_owned());
    }
}

/// A subtree of another seed (`others` is not empty).
fn splice_subtree(rng: &mut Rng, node: &mut Value, others: &[Value]) {
    let o = rng.pick(others);
    let optrs = pointers(o, 4096);
    let p = rng.pick(&optrs);
    if let Some(x) = o.pointer(p) {
        *node = x.clone();
    }
}

/// Tweaks a number; a non-number becomes an interesting one.
fn tweak_number(rng: &mut Rng, node: &mut Value) {
    if let Some(x) = node.as_f64() {
        let y = match rng.below(6) {
            0 => -x,
            1 => x * 10.0,
            2 => x + 1.0,
            3 => x * 1e6,
            4 => x / 1e6,
            _ => x + 1e-12,
        };
        *node = Number::from_f64(y).map_or(Value::Null, Value::Number);
    } else {
        *node = interesting_number(rng);
    }
}

/// Mutates a string's bytes; a non-string becomes a random string.
fn mutate_string(rng: &mut Rng, node: &mut Value) {
    if let Value::String(s) = node {
        let mut b = s.clone().into_bytes();
        bytes::mutate(rng, &mut b, &[]);
        *s = String::from_utf8_lossy(&b).into_owned();
    } else {
        *node = Value::String(random_string(rng));
    }
}

/// Copies another node of the same document (picked from `ptrs`) over the one at `ptr`.
fn copy_other_node(rng: &mut Rng, v: &mut Value, ptrs: &[String], ptr: &str) {
    let p2 = rng.pick(ptrs).clone();
    if let Some(x) = v.pointer(&p2).cloned() {
        if let Some(node) = v.pointer_mut(ptr) {
            *node = x;
        }
    }
}

/// Empties the container or zeroes the scalar.
fn empty_value(node: &mut Value) {
    *node = match node {
        Value::Array(_) => Value::Array(Vec::new()),
        Value::Object(_) => Value::Object(Map::new()),
        Value::String(_) => Value::String(String::new()),
        Value::Number(_) => Value::from(0),
        _ => Value::Null,
    };
}

/// Length of the compact serialisation, counted without building it.
fn compact_len(v: &Value) -> usize {
    struct Count(usize);
    impl std::io::Write for Count {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0 += b.len();
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    let mut c = Count(0);
    let _ = serde_json::to_writer(&mut c, v);
    c.0
}

/// Serialises with the raw substitutions (duplicate-key pairs included).
fn write(v: &Value, raw: &Raw, pretty: bool) -> String {
    let text = if pretty {
        serde_json::to_string_pretty(v)
    } else {
        serde_json::to_string(v)
    }
    .unwrap_or_default();
    let mut text = text;
    // Raw texts and duplicate keys may hold each other's placeholders: two passes.
    for _ in 0..2 {
        // The placeholder pair `"\u0001DUPn\u0001":null` becomes `"k":value`.
        for (quoted, dup) in &raw.pairs {
            text = bounded_replace(&text, &format!("{quoted}:null"), dup);
            text = bounded_replace(&text, &format!("{quoted}: null"), dup);
        }
        text = raw.apply(text);
    }
    text
}

/// Mutates a JSON value `rounds` times and writes it (some of the time pretty, some of the
/// time with a byte mutation on top).
pub fn mutate_value_text(rng: &mut Rng, v: &Value, others: &[Value], rounds: usize) -> Vec<u8> {
    let mut v = v.clone();
    let mut raw = Raw::default();
    for _ in 0..rounds.max(1) {
        let before = v.clone();
        mutate_value(rng, &mut v, others, &mut raw);
        // Copies of copies could grow without bound: undo a round that went over.
        if compact_len(&v) > MAX_OUTPUT {
            v = before;
        }
    }
    // Pretty-printing a deep value with a huge array indents every element: small ones only.
    let pretty = rng.one_in(4) && compact_len(&v) < (1 << 20);
    let mut out = write(&v, &raw, pretty).into_bytes();
    if rng.one_in(6) {
        bytes::mutate(rng, &mut out, &[]);
    }
    out
}

/// Mutates JSON text: structurally when it parses, byte-wise otherwise.
pub fn mutate_text(rng: &mut Rng, text: &[u8], others: &[Value], rounds: usize) -> Vec<u8> {
    match serde_json::from_slice::<Value>(text) {
        Ok(v) => mutate_value_text(rng, &v, others, rounds),
        Err(_) => {
            let mut b = text.to_vec();
            bytes::mutate_n(rng, &mut b, &[], rounds.max(1));
            b
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn duplicate_keys_and_raw_numbers_are_written_textually() {
        let seed: Value = serde_json::json!({"a": 1, "b": {"c": [1, 2]}});
        let (mut dup, mut nan, mut parsed) = (0, 0, 0);
        for i in 0..3000 {
            let mut rng = Rng::for_input("json", 0, i);
            let out = mutate_value_text(&mut rng, &seed, &[], 1);
            let text = String::from_utf8_lossy(&out);
            assert!(!text.contains("\\u0001"), "placeholder left in {text}");
            if text.contains("NaN") || text.contains("Infinity") {
                nan += 1;
            }
            if text.matches("\"a\":").count() >= 2 {
                dup += 1;
            }
            if serde_json::from_slice::<Value>(&out).is_ok() {
                parsed += 1;
            }
        }
        assert!(dup > 5, "{dup} duplicate-key inputs");
        assert!(nan > 5, "{nan} NaN inputs");
        assert!(parsed > 1000, "{parsed} inputs still JSON");
    }
}
