//! Comparing a file's protobuf schema of a raw topic with ours, field by field
//! ([`schema_difference`]).

use super::FILE_DESCRIPTOR_SET;

/// Fields added to format 2 since its first files (message, field number): a file's schema
/// may lack them (a file written before them), and its messages then read them as protobuf's
/// default (0, empty). For scenes of several objects: `FingerContact.object`,
/// `ObjectState.index` and `ObjectState.objects`; for whole-hand contact `FingerContact.part`
/// and `FingerContact.link` (a file without them holds fingertips alone).
pub const ADDED_FIELDS: [(&str, i32); 5] = [
    (".icms.FingerContact", 12),
    (".icms.ObjectState", 8),
    (".icms.ObjectState", 9),
    (".icms.FingerContact", 13),
    (".icms.FingerContact", 14),
];

/// Where the protobuf schema `theirs` (a serialised `FileDescriptorSet`, as a file's schema
/// record holds it) defines message `name` (e.g. `icms.Contacts`) differently from ours:
/// `None` if it is the same (same fields, numbers, types and labels, recursively through the
/// messages it uses; names of files and comments may differ; a field of [`ADDED_FIELDS`] may
/// be missing), else which field differs and how. A raw topic of another layout would decode
/// into wrong numbers, not fail.
pub fn schema_difference(theirs: &[u8], name: &str) -> Option<String> {
    use prost::Message;
    use prost_types::FileDescriptorSet;
    let ours = FileDescriptorSet::decode(FILE_DESCRIPTOR_SET).expect("our descriptor set");
    let theirs = match FileDescriptorSet::decode(theirs) {
        Ok(fds) => fds,
        Err(e) => {
            return Some(format!(
                "the schema is not a protobuf FileDescriptorSet: {e}"
            ))
        }
    };
    let (ours, theirs) = (message_index(&ours), message_index(&theirs));
    let mut seen = std::collections::BTreeSet::new();
    compare_message(&ours, &theirs, &format!(".{name}"), name, &mut seen)
}

type MessageIndex<'a> = std::collections::BTreeMap<String, &'a prost_types::DescriptorProto>;

fn message_index(fds: &prost_types::FileDescriptorSet) -> MessageIndex<'_> {
    fn add<'a>(out: &mut MessageIndex<'a>, scope: &str, m: &'a prost_types::DescriptorProto) {
        let full = format!("{scope}.{}", m.name());
        for nested in &m.nested_type {
            add(out, &full, nested);
        }
        out.insert(full, m);
    }
    let mut out = MessageIndex::new();
    for f in &fds.file {
        let scope = if f.package().is_empty() {
            String::new()
        } else {
            format!(".{}", f.package())
        };
        for m in &f.message_type {
            add(&mut out, &scope, m);
        }
    }
    out
}

fn compare_message(
    ours: &MessageIndex<'_>,
    theirs: &MessageIndex<'_>,
    full: &str,
    path: &str,
    seen: &mut std::collections::BTreeSet<String>,
) -> Option<String> {
    if !seen.insert(full.to_owned()) {
        return None;
    }
    let mine = ours.get(full)?;
    let Some(other) = theirs.get(full) else {
        return Some(format!(
            "{path}: the schema does not define message {}",
            full.trim_start_matches('.')
        ));
    };
    let describe = |f: &prost_types::FieldDescriptorProto| {
        format!(
            "{} {} {} = {}",
            f.label()
                .as_str_name()
                .trim_start_matches("LABEL_")
                .to_lowercase(),
            if f.type_name().is_empty() {
                f.r#type()
                    .as_str_name()
                    .trim_start_matches("TYPE_")
                    .to_lowercase()
            } else {
                f.type_name().trim_start_matches('.').to_owned()
            },
            f.name(),
            f.number()
        )
    };
    for f in &mine.field {
        let at = format!("{path}.{}", f.name());
        let Some(g) = other.field.iter().find(|g| g.number() == f.number()) else {
            if ADDED_FIELDS.contains(&(full, f.number())) {
                continue;
            }
            return Some(format!(
                "{at}: ours is `{}`; the file's schema has no field {}",
                describe(f),
                f.number()
            ));
        };
        if (g.name(), g.r#type(), g.label(), g.type_name())
            != (f.name(), f.r#type(), f.label(), f.type_name())
        {
            return Some(format!(
                "{at}: ours is `{}`, the file's is `{}`",
                describe(f),
                describe(g)
            ));
        }
        if !f.type_name().is_empty() {
            if let Some(d) = compare_message(ours, theirs, f.type_name(), &at, seen) {
                return Some(d);
            }
        }
    }
    if let Some(g) = other
        .field
        .iter()
        .find(|g| !mine.field.iter().any(|f| f.number() == g.number()))
    {
        return Some(format!(
            "{path}.{}: the file's schema has `{}`, which ours has not",
            g.name(),
            describe(g)
        ));
    }
    None
}
