//! [`MessageCheck`]: whether bytes decode as a message type described by a file descriptor
//! set, as prost would decode them, without building anything (the Foxglove topics' check).

use super::fields::count_packed;
use super::reader::{expect, Reader, I32, I64, LEN, VARINT};
use super::Result;

/// What a field's bytes must be, by its type in a message prost decodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FieldKind {
    /// Integers, `bool`, enums: a varint (packed or not if repeated).
    Varint,
    /// `double`, `fixed64`, `sfixed64`: eight bytes (packed or not if repeated).
    Fixed64,
    /// `float`, `fixed32`, `sfixed32`: four bytes (packed or not if repeated).
    Fixed32,
    /// `string`: length-delimited UTF-8.
    Str,
    /// `bytes`: length-delimited.
    Bytes,
    /// An embedded message: the index of its type in [`MessageCheck::messages`].
    Message(usize),
}

/// One field of a message type.
#[derive(Debug, Clone, Copy)]
struct FieldSpec {
    number: u32,
    kind: FieldKind,
    repeated: bool,
}

/// Whether bytes decode as a protobuf message type, as prost decodes them into the Rust type
/// generated from its `.proto` (proto3: unknown fields skipped, groups skipped to prost's
/// recursion limit, packed or unpacked repeated scalars, strings UTF-8): the same bytes
/// accepted and refused, nothing built. Made from the type's file descriptor set; for the
/// Foxglove topics, whose messages prost decoded only to be checked (allocating every
/// string and vector: a tenth of an ingest's CPU).
#[derive(Debug)]
pub(crate) struct MessageCheck {
    /// Per message type, its fields by ascending number.
    messages: Vec<Vec<FieldSpec>>,
    root: usize,
}

impl MessageCheck {
    /// The check of message type `root` (its full name, `foxglove.SceneUpdate`) described in
    /// `descriptor_set` (a serialized `FileDescriptorSet` holding it and its dependencies);
    /// `None` if it does not describe it (or uses groups).
    pub(crate) fn new(descriptor_set: &[u8], root: &str) -> Option<MessageCheck> {
        use prost::Message;
        use prost_types::field_descriptor_proto::{Label, Type};
        use prost_types::DescriptorProto;
        fn collect<'d>(
            prefix: &str,
            types: &'d [DescriptorProto],
            out: &mut Vec<(String, &'d DescriptorProto)>,
        ) {
            for t in types {
                let name = format!("{prefix}.{}", t.name());
                collect(&name, &t.nested_type, out);
                out.push((name, t));
            }
        }
        let set = prost_types::FileDescriptorSet::decode(descriptor_set).ok()?;
        let mut types = Vec::new();
        for file in &set.file {
            let prefix = match file.package() {
                "" => String::new(),
                p => format!(".{p}"),
            };
            collect(&prefix, &file.message_type, &mut types);
        }
        let index = |name: &str| types.iter().position(|(n, _)| n == name);
        let mut messages = Vec::with_capacity(types.len());
        for (_, t) in &types {
            let mut fields = Vec::with_capacity(t.field.len());
            for f in &t.field {
                let kind = match Type::try_from(f.r#type?).ok()? {
                    Type::Double | Type::Fixed64 | Type::Sfixed64 => FieldKind::Fixed64,
                    Type::Float | Type::Fixed32 | Type::Sfixed32 => FieldKind::Fixed32,
                    Type::Int64
                    | Type::Uint64
                    | Type::Int32
                    | Type::Uint32
                    | Type::Sint32
                    | Type::Sint64
                    | Type::Bool
                    | Type::Enum => FieldKind::Varint,
                    Type::String => FieldKind::Str,
                    Type::Bytes => FieldKind::Bytes,
                    Type::Message => FieldKind::Message(index(f.type_name())?),
                    Type::Group => return None,
                };
                fields.push(FieldSpec {
                    number: u32::try_from(f.number()).ok()?,
                    kind,
                    repeated: f.label() == Label::Repeated,
                });
            }
            fields.sort_by_key(|f| f.number);
            messages.push(fields);
        }
        let root = index(&format!(".{root}"))?;
        Some(MessageCheck { messages, root })
    }

    /// `Ok` if `buf` decodes as the message type, as prost would decode it.
    pub(crate) fn check(&self, buf: &[u8]) -> Result<()> {
        self.message(&mut Reader::new(buf), self.root)
    }

    fn message(&self, r: &mut Reader<'_>, message: usize) -> Result<()> {
        let fields = &self.messages[message];
        while !r.is_empty() {
            let (tag, wire) = r.key()?;
            match fields.iter().find(|f| f.number == tag) {
                Some(f) => self.field(r, f, wire)?,
                None => r.skip(tag, wire)?,
            }
        }
        Ok(())
    }

    fn field(&self, r: &mut Reader<'_>, f: &FieldSpec, wire: u8) -> Result<()> {
        // Repeated scalars come packed (length-delimited) or one by one.
        let packed = f.repeated && wire == LEN;
        let fixed = |r: &mut Reader<'_>, size: usize, one: u8| {
            if packed {
                // Values cut by the field's end: prost reads past it and fails.
                if r.len_delimited()?.len() % size != 0 {
                    return Err("delimited length exceeded");
                }
                Ok(())
            } else {
                expect(wire, one)?;
                r.take(size).map(drop)
            }
        };
        match f.kind {
            FieldKind::Varint if packed => count_packed(r.len_delimited()?).map(drop),
            FieldKind::Varint => {
                expect(wire, VARINT)?;
                r.varint().map(drop)
            }
            FieldKind::Fixed64 => fixed(r, 8, I64),
            FieldKind::Fixed32 => fixed(r, 4, I32),
            FieldKind::Str => {
                expect(wire, LEN)?;
                std::str::from_utf8(r.len_delimited()?)
                    .map(drop)
                    .map_err(|_| "invalid string value: data is not UTF-8 encoded")
            }
            FieldKind::Bytes => {
                expect(wire, LEN)?;
                r.len_delimited().map(drop)
            }
            FieldKind::Message(m) => {
                let mut inner = r.nested(wire)?;
                self.message(&mut inner, m)
            }
        }
    }
}
