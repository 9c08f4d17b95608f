//! A YAML document as a tree of nodes that remember where they came from, and a serde
//! `Deserializer` over that tree whose errors carry the line, column and field path of the node
//! that failed.
//!
//! Parsing the whole file once into this tree (stage "parse") and then deserialising each section
//! from it separately (stage "schema") lets validation report every broken section of a mission
//! in one run, each error pointing at its exact place.

use std::fmt;

use serde::de::{
    self, Deserialize, DeserializeSeed, Deserializer, EnumAccess, IntoDeserializer, MapAccess, SeqAccess,
    VariantAccess, Visitor,
};
use serde_saphyr::Spanned;

/// A position in a source file, 1-based.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Loc {
    /// Line, from 1 (0 = unknown).
    pub line: u32,
    /// Column in characters, from 1 (0 = unknown).
    pub column: u32,
    /// Byte offset into the source, when known.
    pub offset: Option<usize>,
    /// Length in bytes of the spanned text, when known.
    pub len: usize,
}

impl Loc {
    fn from_saphyr(l: &serde_saphyr::Location) -> Self {
        let span = l.span();
        Loc {
            line: l.line() as u32,
            column: l.column() as u32,
            offset: span.byte_offset().map(|o| o as usize),
            len: span.byte_len().map_or(0, |n| n as usize),
        }
    }
}

impl fmt::Display for Loc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.line, self.column)
    }
}

/// A YAML value with its location.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    /// Where the value starts.
    pub loc: Loc,
    /// The value.
    pub value: Value,
}

/// A YAML value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `~`, `null` or nothing.
    Null,
    /// A boolean.
    Bool(bool),
    /// An integer.
    Int(i64),
    /// A floating-point number.
    Float(f64),
    /// A string.
    Str(String),
    /// A sequence.
    Seq(Vec<Node>),
    /// A mapping, in file order; keys are strings with their own locations.
    Map(Vec<(Key, Node)>),
}

/// A mapping key with its location.
#[derive(Clone, Debug, PartialEq)]
pub struct Key {
    /// Where the key is written.
    pub loc: Loc,
    /// The key text.
    pub name: String,
}

impl Value {
    /// A short name of the kind of value, for "expected …, found …" messages.
    pub fn kind(&self) -> &'static str {
        match self {
            Value::Null => "null",
            Value::Bool(_) => "a boolean",
            Value::Int(_) => "an integer",
            Value::Float(_) => "a number",
            Value::Str(_) => "a string",
            Value::Seq(_) => "a list",
            Value::Map(_) => "a mapping",
        }
    }
}

impl Node {
    /// The entries if this is a mapping.
    pub fn as_map(&self) -> Option<&[(Key, Node)]> {
        match &self.value {
            Value::Map(m) => Some(m),
            _ => None,
        }
    }

    /// The items if this is a sequence.
    pub fn as_seq(&self) -> Option<&[Node]> {
        match &self.value {
            Value::Seq(s) => Some(s),
            _ => None,
        }
    }

    /// The text if this is a string.
    pub fn as_str(&self) -> Option<&str> {
        match &self.value {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    /// The number if this is an integer or a float.
    pub fn as_f64(&self) -> Option<f64> {
        match self.value {
            Value::Int(i) => Some(i as f64),
            Value::Float(f) => Some(f),
            _ => None,
        }
    }

    /// The value of `key` if this is a mapping that has it.
    pub fn get(&self, key: &str) -> Option<&Node> {
        self.as_map()?.iter().find(|(k, _)| k.name == key).map(|(_, v)| v)
    }

    /// The key entry (with its location) named `key`.
    pub fn key(&self, key: &str) -> Option<&Key> {
        self.as_map()?.iter().find(|(k, _)| k.name == key).map(|(k, _)| k)
    }

    /// Deserialises a typed value from this node; errors carry the location and field path of
    /// the part that failed.
    pub fn deserialize<T: for<'de> Deserialize<'de>>(&self) -> Result<T, DeError> {
        T::deserialize(NodeDeserializer { node: self })
    }

    /// Converts to JSON (for parameter blocks handed to node factories and for `--json`).
    pub fn to_json(&self) -> serde_json::Value {
        match &self.value {
            Value::Null => serde_json::Value::Null,
            Value::Bool(b) => (*b).into(),
            Value::Int(i) => (*i).into(),
            Value::Float(f) => serde_json::Number::from_f64(*f).map_or(serde_json::Value::Null, Into::into),
            Value::Str(s) => s.clone().into(),
            Value::Seq(s) => s.iter().map(Node::to_json).collect(),
            Value::Map(m) => m.iter().map(|(k, v)| (k.name.clone(), v.to_json())).collect(),
        }
    }
}

/// Why a document did not parse as YAML.
#[derive(Debug, Clone)]
pub struct ParseError {
    /// Where the parser stopped.
    pub loc: Loc,
    /// What it said.
    pub message: String,
}

/// Parses YAML text into a [`Node`] tree. Duplicate keys are errors.
pub fn parse(text: &str) -> Result<Node, ParseError> {
    if text.trim().is_empty() {
        return Err(ParseError {
            loc: Loc { line: 1, column: 1, offset: Some(0), len: 0 },
            message: "the file is empty".into(),
        });
    }
    let raw: Spanned<Raw> = serde_saphyr::from_str(text).map_err(|e| {
        let loc = e.location().map(|l| Loc::from_saphyr(&l)).unwrap_or_default();
        ParseError { loc, message: saphyr_message(&e) }
    })?;
    Ok(into_node(raw))
}

/// The message of a serde-saphyr error without its location prefix and source snippet (we
/// render our own).
fn saphyr_message(e: &serde_saphyr::Error) -> String {
    let text = e.to_string();
    let first = text.lines().next().unwrap_or_default();
    let first = first.strip_prefix("error: ").unwrap_or(first);
    // "line L column C: message"
    let message = match first.split_once(": ") {
        Some((head, rest)) if head.starts_with("line ") => rest,
        _ => first,
    };
    user_message(message)
}

/// The parser's message in the mission author's terms: what to change in the file, not which
/// option of the parser to set.
fn user_message(message: &str) -> String {
    if let Some(rest) = message.strip_prefix("duplicate mapping key") {
        let key = rest.split(", set DuplicateKeyPolicy").next().unwrap_or_default().trim_start_matches(": ");
        let key = if key.starts_with(", set") || key.is_empty() { String::new() } else { format!(" `{key}`") };
        return format!("duplicate key{key}: a key may appear once in a mapping; remove or rename one of them");
    }
    if let Some(rest) = message.strip_prefix("non-finite float ") {
        // "`.nan` rejected by the configured policy"
        let value = rest.split(" rejected").next().unwrap_or_default();
        return format!("{value} is not a finite number; NaN and infinities are not accepted, write a finite number");
    }
    if let Some(breach) = message.strip_prefix("budget breached: ") {
        // `Depth { depth: 65 }`: the limit's name, then the count that passed it.
        let name = breach.split([' ', '{']).next().unwrap_or_default();
        let count: String = breach.chars().filter(char::is_ascii_digit).collect();
        let what = match name {
            "Depth" => "nests too deeply",
            "Events" | "Nodes" => "has too many values",
            "Aliases" => "uses aliases (`*name`) too often",
            "Anchors" => "has too many anchors (`&name`)",
            "Documents" => "has too many documents (`---`)",
            "InclusionDepth" => "nests includes too deeply",
            _ => "is too large or too complex",
        };
        let at = if count.is_empty() { String::new() } else { format!(" ({count} reached)") };
        return format!("the YAML {what} for a mission file{at}; simplify it");
    }
    message.to_string()
}

/// The shape serde-saphyr fills in; converted to [`Node`] right after.
enum Raw {
    Null,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    Seq(Vec<Spanned<Raw>>),
    Map(Vec<(Spanned<String>, Spanned<Raw>)>),
}

fn into_node(raw: Spanned<Raw>) -> Node {
    let loc = Loc::from_saphyr(&raw.referenced);
    let value = match raw.value {
        Raw::Null => Value::Null,
        Raw::Bool(b) => Value::Bool(b),
        Raw::Int(i) => Value::Int(i),
        Raw::Float(f) => Value::Float(f),
        Raw::Str(s) => Value::Str(s),
        Raw::Seq(items) => Value::Seq(items.into_iter().map(into_node).collect()),
        Raw::Map(entries) => Value::Map(
            entries
                .into_iter()
                .map(|(k, v)| (Key { loc: Loc::from_saphyr(&k.referenced), name: k.value }, into_node(v)))
                .collect(),
        ),
    };
    Node { loc, value }
}

impl<'de> Deserialize<'de> for Raw {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct RawVisitor;
        impl<'de> Visitor<'de> for RawVisitor {
            type Value = Raw;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("any YAML value")
            }
            fn visit_unit<E>(self) -> Result<Raw, E> {
                Ok(Raw::Null)
            }
            fn visit_none<E>(self) -> Result<Raw, E> {
                Ok(Raw::Null)
            }
            fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Raw, D::Error> {
                Raw::deserialize(d)
            }
            fn visit_bool<E>(self, v: bool) -> Result<Raw, E> {
                Ok(Raw::Bool(v))
            }
            fn visit_i64<E>(self, v: i64) -> Result<Raw, E> {
                Ok(Raw::Int(v))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Raw, E> {
                i64::try_from(v).map(Raw::Int).or(Ok(Raw::Float(v as f64)))
            }
            fn visit_i128<E>(self, v: i128) -> Result<Raw, E> {
                Ok(i64::try_from(v).map_or(Raw::Float(v as f64), Raw::Int))
            }
            fn visit_u128<E>(self, v: u128) -> Result<Raw, E> {
                Ok(i64::try_from(v).map_or(Raw::Float(v as f64), Raw::Int))
            }
            fn visit_f64<E>(self, v: f64) -> Result<Raw, E> {
                Ok(Raw::Float(v))
            }
            fn visit_str<E>(self, v: &str) -> Result<Raw, E> {
                Ok(Raw::Str(v.to_owned()))
            }
            fn visit_string<E>(self, v: String) -> Result<Raw, E> {
                Ok(Raw::Str(v))
            }
            fn visit_bytes<E: de::Error>(self, v: &[u8]) -> Result<Raw, E> {
                Ok(Raw::Str(String::from_utf8_lossy(v).into_owned()))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut a: A) -> Result<Raw, A::Error> {
                let mut items = Vec::new();
                while let Some(item) = a.next_element()? {
                    items.push(item);
                }
                Ok(Raw::Seq(items))
            }
            fn visit_map<A: MapAccess<'de>>(self, mut a: A) -> Result<Raw, A::Error> {
                let mut entries = Vec::new();
                while let Some(k) = a.next_key::<Spanned<String>>()? {
                    let v = a.next_value()?;
                    entries.push((k, v));
                }
                Ok(Raw::Map(entries))
            }
        }
        d.deserialize_any(RawVisitor)
    }
}

/// A deserialisation error with the place it happened.
#[derive(Debug, Clone, PartialEq)]
pub struct DeError {
    /// What went wrong.
    pub message: String,
    /// Where (the innermost node that failed), if known yet.
    pub loc: Option<Loc>,
    /// Field path from the node deserialised, e.g. `team[1].priority`.
    pub path: Vec<PathSeg>,
}

/// One step of a field path.
#[derive(Debug, Clone, PartialEq)]
pub enum PathSeg {
    /// A mapping key.
    Key(String),
    /// A list index.
    Index(usize),
}

impl DeError {
    /// The field path as text (`a.b[2].c`), relative to the deserialised node.
    pub fn path_string(&self) -> String {
        render_path(&self.path)
    }

    fn at(mut self, loc: Loc) -> Self {
        self.loc.get_or_insert(loc);
        self
    }

    fn within(mut self, seg: PathSeg) -> Self {
        self.path.insert(0, seg);
        self
    }
}

/// Renders a path as `a.b[2].c`.
pub fn render_path(path: &[PathSeg]) -> String {
    let mut s = String::new();
    for seg in path {
        match seg {
            PathSeg::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            PathSeg::Index(i) => {
                s.push_str(&format!("[{i}]"));
            }
        }
    }
    s
}

impl fmt::Display for DeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for DeError {}

impl de::Error for DeError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        DeError { message: msg.to_string(), loc: None, path: Vec::new() }
    }

    fn invalid_type(unexp: de::Unexpected<'_>, exp: &dyn de::Expected) -> Self {
        Self::custom(format_args!("invalid type: {}, expected {exp}", unexpected(unexp)))
    }

    fn invalid_value(unexp: de::Unexpected<'_>, exp: &dyn de::Expected) -> Self {
        Self::custom(format_args!("invalid value: {}, expected {exp}", unexpected(unexp)))
    }

    fn unknown_variant(variant: &str, expected: &'static [&'static str]) -> Self {
        let found = match unexpected(de::Unexpected::Str(variant)) {
            long if long.starts_with("a string of") => long,
            _ => format!("`{variant}`"),
        };
        match expected {
            [] => Self::custom(format_args!("unknown variant {found}, there are no variants")),
            _ => Self::custom(format_args!("unknown variant {found}, expected one of `{}`", expected.join("`, `"))),
        }
    }
}

/// What was found, for an error message: a long or multi-line string is named by its length,
/// not quoted, so that a file that is not what was asked for (a key, a password file, an
/// `.env`) does not end up printed in the error.
fn unexpected(unexp: de::Unexpected<'_>) -> String {
    match unexp {
        de::Unexpected::Str(s) if s.chars().count() > MAX_QUOTED_CHARS || s.contains('\n') => {
            format!("a string of {} characters", s.chars().count())
        }
        other => other.to_string(),
    }
}

/// The longest string value an error message quotes; longer ones are named by their length.
pub const MAX_QUOTED_CHARS: usize = 40;

/// The serde deserializer over a [`Node`].
struct NodeDeserializer<'a> {
    node: &'a Node,
}

impl<'a> NodeDeserializer<'a> {
    fn invalid(&self, exp: &dyn de::Expected) -> DeError {
        let unexp = match &self.node.value {
            Value::Null => de::Unexpected::Unit,
            Value::Bool(b) => de::Unexpected::Bool(*b),
            Value::Int(i) => de::Unexpected::Signed(*i),
            Value::Float(f) => de::Unexpected::Float(*f),
            Value::Str(s) => de::Unexpected::Str(s),
            Value::Seq(_) => de::Unexpected::Seq,
            Value::Map(_) => de::Unexpected::Map,
        };
        <DeError as de::Error>::invalid_type(unexp, exp).at(self.node.loc)
    }
}

impl<'de, 'a> Deserializer<'de> for NodeDeserializer<'a> {
    type Error = DeError;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        let loc = self.node.loc;
        let r = match &self.node.value {
            Value::Null => visitor.visit_unit(),
            Value::Bool(b) => visitor.visit_bool(*b),
            Value::Int(i) => visitor.visit_i64(*i),
            Value::Float(f) => visitor.visit_f64(*f),
            Value::Str(s) => visitor.visit_str(s),
            Value::Seq(items) => visitor.visit_seq(NodeSeq { iter: items.iter().enumerate() }),
            Value::Map(entries) => visitor.visit_map(NodeMap { iter: entries.iter(), value: None }),
        };
        r.map_err(|e| e.at(loc))
    }

    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        match self.node.value {
            Value::Null => visitor.visit_none(),
            _ => visitor.visit_some(self),
        }
    }

    fn deserialize_f64<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        // Integers are fine where a number is expected: `duration_s: 5`.
        match self.node.value {
            Value::Int(i) => visitor.visit_f64(i as f64).map_err(|e: DeError| e.at(self.node.loc)),
            _ => self.deserialize_any(visitor),
        }
    }

    fn deserialize_f32<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        self.deserialize_f64(visitor)
    }

    fn deserialize_string<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        match &self.node.value {
            Value::Str(s) => visitor.visit_str(s).map_err(|e: DeError| e.at(self.node.loc)),
            _ => Err(self.invalid(&visitor)),
        }
    }

    fn deserialize_str<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        self.deserialize_string(visitor)
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _variants: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, DeError> {
        let loc = self.node.loc;
        match &self.node.value {
            Value::Str(s) => visitor.visit_enum(s.as_str().into_deserializer()).map_err(|e: DeError| e.at(loc)),
            Value::Map(entries) if entries.len() == 1 => {
                let (k, v) = &entries[0];
                visitor
                    .visit_enum(NodeEnum { key: k, value: v })
                    .map_err(|e| e.within(PathSeg::Key(k.name.clone())).at(k.loc))
            }
            _ => Err(self.invalid(&"a name, or a mapping with exactly one key")),
        }
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(self, _name: &'static str, visitor: V) -> Result<V::Value, DeError> {
        visitor.visit_newtype_struct(self)
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 char bytes byte_buf unit unit_struct seq
        tuple tuple_struct map struct identifier ignored_any
    }
}

struct NodeSeq<'a> {
    iter: std::iter::Enumerate<std::slice::Iter<'a, Node>>,
}

impl<'de, 'a> SeqAccess<'de> for NodeSeq<'a> {
    type Error = DeError;
    fn next_element_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Result<Option<T::Value>, DeError> {
        match self.iter.next() {
            None => Ok(None),
            Some((i, node)) => seed
                .deserialize(NodeDeserializer { node })
                .map(Some)
                .map_err(|e| e.at(node.loc).within(PathSeg::Index(i))),
        }
    }
}

struct NodeMap<'a> {
    iter: std::slice::Iter<'a, (Key, Node)>,
    value: Option<(&'a Key, &'a Node)>,
}

impl<'de, 'a> MapAccess<'de> for NodeMap<'a> {
    type Error = DeError;
    fn next_key_seed<K: DeserializeSeed<'de>>(&mut self, seed: K) -> Result<Option<K::Value>, DeError> {
        match self.iter.next() {
            None => Ok(None),
            Some((k, v)) => {
                self.value = Some((k, v));
                seed.deserialize(k.name.as_str().into_deserializer())
                    .map(Some)
                    .map_err(|e: DeError| e.at(k.loc).within(PathSeg::Key(k.name.clone())))
            }
        }
    }
    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, DeError> {
        let Some((k, node)) = self.value.take() else {
            return Err(<DeError as de::Error>::custom("value requested before key"));
        };
        seed.deserialize(NodeDeserializer { node }).map_err(|e| e.at(node.loc).within(PathSeg::Key(k.name.clone())))
    }
}

struct NodeEnum<'a> {
    key: &'a Key,
    value: &'a Node,
}

impl<'de, 'a> EnumAccess<'de> for NodeEnum<'a> {
    type Error = DeError;
    type Variant = NodeVariant<'a>;
    fn variant_seed<V: DeserializeSeed<'de>>(self, seed: V) -> Result<(V::Value, NodeVariant<'a>), DeError> {
        let v = seed.deserialize(self.key.name.as_str().into_deserializer())?;
        Ok((v, NodeVariant { node: self.value }))
    }
}

struct NodeVariant<'a> {
    node: &'a Node,
}

impl<'de, 'a> VariantAccess<'de> for NodeVariant<'a> {
    type Error = DeError;
    fn unit_variant(self) -> Result<(), DeError> {
        match self.node.value {
            Value::Null => Ok(()),
            _ => Err(NodeDeserializer { node: self.node }.invalid(&"nothing after a unit variant")),
        }
    }
    fn newtype_variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<T::Value, DeError> {
        seed.deserialize(NodeDeserializer { node: self.node })
    }
    fn tuple_variant<V: Visitor<'de>>(self, _len: usize, visitor: V) -> Result<V::Value, DeError> {
        NodeDeserializer { node: self.node }.deserialize_any(visitor)
    }
    fn struct_variant<V: Visitor<'de>>(
        self,
        _fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, DeError> {
        NodeDeserializer { node: self.node }.deserialize_any(visitor)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Robot {
        id: String,
        priority: u32,
    }

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Doc {
        team: Vec<Robot>,
    }

    #[test]
    fn errors_point_at_the_failing_field() {
        let node = parse("team:\n  - id: a\n    priority: 1\n  - id: b\n    priority: high\n").unwrap();
        let err = node.deserialize::<Doc>().unwrap_err();
        assert_eq!(err.path_string(), "team[1].priority");
        let loc = err.loc.unwrap();
        assert_eq!((loc.line, loc.column), (5, 15));
        assert!(err.message.contains("expected u32"), "{}", err.message);
    }

    #[test]
    fn unknown_keys_point_at_the_key() {
        let node = parse("team:\n  - id: a\n    priority: 1\n    colour: red\n").unwrap();
        let err = node.deserialize::<Doc>().unwrap_err();
        assert_eq!(err.path_string(), "team[0].colour");
        let loc = err.loc.unwrap();
        assert_eq!((loc.line, loc.column), (4, 5));
        assert!(err.message.contains("unknown field `colour`"), "{}", err.message);
    }

    #[test]
    fn missing_fields_point_at_the_mapping() {
        let node = parse("team:\n  - id: a\n").unwrap();
        let err = node.deserialize::<Doc>().unwrap_err();
        assert_eq!(err.path_string(), "team[0]");
        assert_eq!(err.loc.unwrap().line, 2);
        assert!(err.message.contains("missing field `priority`"));
    }

    #[test]
    fn syntax_errors_have_a_location() {
        let err = parse("a: [1, 2\nb: 3\n").unwrap_err();
        assert_eq!(err.loc.line, 2);
        assert!(!err.message.contains("-->"), "no snippet in the message: {}", err.message);
        let dup = parse("a: 1\na: 2\n").unwrap_err();
        assert_eq!(dup.loc.line, 2);
        assert!(dup.message.contains("duplicate"));
    }
}
