//! The typed per-robot blackboard.
//!
//! Keys are interned when a tree is built, so a node reads and writes by index, never by string,
//! and every key has one declared [`PortType`] that the loader checked against every port wired
//! to it.

use std::collections::HashMap;
use std::fmt;
use std::sync::Arc;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::{GoalId, Point2, Pose2, RobotId};

/// The type of a port or blackboard entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum PortType {
    /// `true` / `false`.
    Bool,
    /// A whole number.
    Int,
    /// A number (seconds, metres, …: the port name carries the unit).
    Float,
    /// Text.
    String,
    /// A map-frame point `{x, y}`.
    Point,
    /// A map-frame pose `{x, y, yaw}`.
    Pose,
    /// A goal id.
    Goal,
    /// A robot id.
    Robot,
    /// A list of points `[{x, y}, …]`.
    Points,
    /// A block of parameters for a skill (literal only, checked by the node that takes it).
    Params,
    /// Anything (generic utility nodes).
    Any,
}

impl PortType {
    /// Lower-case name, as written in missions and the manifest.
    pub fn as_str(self) -> &'static str {
        match self {
            PortType::Bool => "bool",
            PortType::Int => "int",
            PortType::Float => "float",
            PortType::String => "string",
            PortType::Point => "point",
            PortType::Pose => "pose",
            PortType::Goal => "goal",
            PortType::Robot => "robot",
            PortType::Points => "points",
            PortType::Params => "params",
            PortType::Any => "any",
        }
    }

    /// Whether a value of type `other` can flow into a port of this type.
    pub fn accepts(self, other: PortType) -> bool {
        self == other
            || self == PortType::Any
            || other == PortType::Any
            || (self == PortType::Float && other == PortType::Int)
    }
}

impl fmt::Display for PortType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A value on the blackboard or bound to a port.
#[derive(Clone, Debug, PartialEq)]
pub enum BbValue {
    /// Boolean.
    Bool(bool),
    /// Integer.
    Int(i64),
    /// Number.
    Float(f64),
    /// Text.
    Str(Arc<str>),
    /// Point.
    Point(Point2),
    /// Pose.
    Pose(Pose2),
    /// Goal id.
    Goal(GoalId),
    /// Robot id.
    Robot(RobotId),
    /// Points.
    Points(Arc<Vec<Point2>>),
    /// A parameter block.
    Params(Arc<serde_json::Value>),
}

impl From<bool> for BbValue {
    fn from(v: bool) -> Self {
        BbValue::Bool(v)
    }
}

impl From<i64> for BbValue {
    fn from(v: i64) -> Self {
        BbValue::Int(v)
    }
}

impl From<f64> for BbValue {
    fn from(v: f64) -> Self {
        BbValue::Float(v)
    }
}

impl From<&str> for BbValue {
    fn from(v: &str) -> Self {
        BbValue::Str(Arc::from(v))
    }
}

impl BbValue {
    /// The type of this value.
    pub fn port_type(&self) -> PortType {
        match self {
            BbValue::Bool(_) => PortType::Bool,
            BbValue::Int(_) => PortType::Int,
            BbValue::Float(_) => PortType::Float,
            BbValue::Str(_) => PortType::String,
            BbValue::Point(_) => PortType::Point,
            BbValue::Pose(_) => PortType::Pose,
            BbValue::Goal(_) => PortType::Goal,
            BbValue::Robot(_) => PortType::Robot,
            BbValue::Points(_) => PortType::Points,
            BbValue::Params(_) => PortType::Params,
        }
    }

    /// The value as a JSON literal [`BbValue::from_json`] reads back; None for a goal (goals
    /// are never written literally).
    pub fn to_json(&self) -> Option<serde_json::Value> {
        use serde_json::json;
        Some(match self {
            BbValue::Bool(b) => json!(b),
            BbValue::Int(i) => json!(i),
            BbValue::Float(f) => json!(f),
            BbValue::Str(s) => json!(s.as_ref()),
            BbValue::Point(p) => serde_json::to_value(p).ok()?,
            BbValue::Pose(p) => serde_json::to_value(p).ok()?,
            BbValue::Goal(_) => return None,
            BbValue::Robot(r) => json!(r.as_str()),
            BbValue::Points(p) => serde_json::to_value(p.as_ref()).ok()?,
            BbValue::Params(v) => (**v).clone(),
        })
    }

    /// A value of type `ty` from a JSON literal, or why not.
    pub fn from_json(ty: PortType, v: &serde_json::Value) -> Result<BbValue, String> {
        fn expected(what: &str, v: &serde_json::Value) -> String {
            format!("expected {what}, found {}", json_kind(v))
        }
        Ok(match ty {
            PortType::Bool => BbValue::Bool(v.as_bool().ok_or_else(|| expected("true or false", v))?),
            PortType::Int => BbValue::Int(v.as_i64().ok_or_else(|| expected("an integer", v))?),
            PortType::Float => {
                let f = v.as_f64().ok_or_else(|| expected("a number", v))?;
                if !f.is_finite() {
                    return Err("expected a finite number".into());
                }
                BbValue::Float(f)
            }
            PortType::String => BbValue::Str(Arc::from(v.as_str().ok_or_else(|| expected("a string", v))?)),
            PortType::Point => BbValue::Point(
                serde_json::from_value(v.clone()).map_err(|e| format!("expected a point {{x, y}}: {e}"))?,
            ),
            PortType::Pose => BbValue::Pose(
                serde_json::from_value(v.clone()).map_err(|e| format!("expected a pose {{x, y, yaw}}: {e}"))?,
            ),
            PortType::Goal => {
                return Err("a goal cannot be written literally; wire it to a blackboard entry like \"{goal}\"".into());
            }
            PortType::Robot => BbValue::Robot(RobotId::new(v.as_str().ok_or_else(|| expected("a robot id", v))?)),
            PortType::Points => BbValue::Points(Arc::new(
                serde_json::from_value(v.clone())
                    .map_err(|e| format!("expected a list of points [{{x, y}}, …]: {e}"))?,
            )),
            PortType::Params => {
                if !v.is_object() {
                    return Err(expected("a mapping of parameters", v));
                }
                BbValue::Params(Arc::new(v.clone()))
            }
            PortType::Any => match v {
                serde_json::Value::Bool(b) => BbValue::Bool(*b),
                serde_json::Value::Number(n) if n.is_i64() => BbValue::Int(n.as_i64().unwrap_or_default()),
                serde_json::Value::Number(n) => BbValue::Float(n.as_f64().unwrap_or_default()),
                serde_json::Value::String(s) => BbValue::Str(Arc::from(s.as_str())),
                other => BbValue::Params(Arc::new(other.clone())),
            },
        })
    }
}

/// A short description of a JSON value's kind.
pub fn json_kind(v: &serde_json::Value) -> &'static str {
    match v {
        serde_json::Value::Null => "nothing",
        serde_json::Value::Bool(_) => "a boolean",
        serde_json::Value::Number(_) => "a number",
        serde_json::Value::String(_) => "a string",
        serde_json::Value::Array(_) => "a list",
        serde_json::Value::Object(_) => "a mapping",
    }
}

/// An interned blackboard key.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BbKey(pub(crate) u32);

/// The blackboard of one robot.
#[derive(Debug, Default)]
pub struct Blackboard {
    names: Vec<Arc<str>>,
    types: Vec<PortType>,
    values: Vec<Option<BbValue>>,
    index: HashMap<Arc<str>, BbKey>,
    events_now: Vec<Arc<str>>,
    events_prev: Vec<Arc<str>>,
    reports: Vec<String>,
}

impl Blackboard {
    /// An empty blackboard.
    pub fn new() -> Self {
        Self::default()
    }

    /// Declares (or finds) a key of a type. The loader has already checked type consistency; a
    /// later declaration with another type keeps the first.
    pub fn declare(&mut self, name: &str, ty: PortType) -> BbKey {
        if let Some(&k) = self.index.get(name) {
            return k;
        }
        let k = BbKey(self.names.len() as u32);
        let name: Arc<str> = Arc::from(name);
        self.names.push(name.clone());
        self.types.push(ty);
        self.values.push(None);
        self.index.insert(name, k);
        k
    }

    /// The key of a name, if declared.
    pub fn key(&self, name: &str) -> Option<BbKey> {
        self.index.get(name).copied()
    }

    /// Name of a key.
    pub fn name(&self, key: BbKey) -> &str {
        &self.names[key.0 as usize]
    }

    /// Declared type of a key.
    pub fn port_type(&self, key: BbKey) -> PortType {
        self.types[key.0 as usize]
    }

    /// The value of a key, if written.
    #[inline]
    pub fn get(&self, key: BbKey) -> Option<&BbValue> {
        self.values.get(key.0 as usize).and_then(Option::as_ref)
    }

    /// Writes a key. Returns false (and writes nothing) if the value's type does not fit.
    pub fn set(&mut self, key: BbKey, value: BbValue) -> bool {
        let i = key.0 as usize;
        let Some(&ty) = self.types.get(i) else { return false };
        if !ty.accepts(value.port_type()) {
            return false;
        }
        let value = match (ty, value) {
            (PortType::Float, BbValue::Int(n)) => BbValue::Float(n as f64),
            (_, v) => v,
        };
        self.values[i] = Some(value);
        true
    }

    /// Erases a key's value.
    pub fn clear(&mut self, key: BbKey) {
        if let Some(v) = self.values.get_mut(key.0 as usize) {
            *v = None;
        }
    }

    /// Writes by name, declaring the key with the value's type if needed.
    pub fn set_by_name(&mut self, name: &str, value: BbValue) -> bool {
        let k = self.declare(name, value.port_type());
        self.set(k, value)
    }

    /// Reads by name.
    pub fn get_by_name(&self, name: &str) -> Option<&BbValue> {
        self.key(name).and_then(|k| self.get(k))
    }

    /// Every written entry, for traces and logs.
    pub fn entries(&self) -> impl Iterator<Item = (&str, &BbValue)> {
        self.names.iter().zip(&self.values).filter_map(|(n, v)| v.as_ref().map(|v| (&**n, v)))
    }

    /// Raises an event; state-machine transitions `on: event` see it during this tick and the
    /// next.
    pub fn raise_event(&mut self, name: &str) {
        if !self.events_now.iter().any(|e| &**e == name) {
            self.events_now.push(Arc::from(name));
        }
    }

    /// Whether an event was raised this tick or the previous one.
    pub fn has_event(&self, name: &str) -> bool {
        self.events_now.iter().chain(&self.events_prev).any(|e| &**e == name)
    }

    /// Consumes an event so a second transition does not fire on it.
    pub fn take_event(&mut self, name: &str) -> bool {
        let before = self.events_now.len() + self.events_prev.len();
        self.events_now.retain(|e| &**e != name);
        self.events_prev.retain(|e| &**e != name);
        before != self.events_now.len() + self.events_prev.len()
    }

    /// Records a runtime diagnostic from a node (a failure reason, a misuse); the executor
    /// collects them into the run's log and summary.
    pub fn report(&mut self, message: impl Into<String>) {
        self.reports.push(message.into());
    }

    /// Takes the diagnostics reported so far.
    pub fn take_reports(&mut self) -> Vec<String> {
        std::mem::take(&mut self.reports)
    }

    /// Ages events by one tick (called by the executor after each root tick).
    pub fn end_tick(&mut self) {
        self.events_prev.clear();
        std::mem::swap(&mut self.events_prev, &mut self.events_now);
    }
}

/// How a node's port is bound: a literal from the mission or a blackboard entry.
#[derive(Clone, Debug, PartialEq)]
pub enum Binding {
    /// A value written in the mission.
    Literal(BbValue),
    /// A `{name}` reference.
    Entry(BbKey),
    /// Not set and no default: an optional port left open.
    Unset,
}

/// Conversion from a blackboard value, for typed port reads.
pub trait FromBb: Sized {
    /// The value, if it has the right type.
    fn from_bb(v: &BbValue) -> Option<Self>;
}

macro_rules! from_bb {
    ($t:ty, $($pat:pat => $e:expr),+) => {
        impl FromBb for $t {
            fn from_bb(v: &BbValue) -> Option<Self> {
                match v { $($pat => Some($e),)+ _ => None }
            }
        }
    };
}

from_bb!(bool, BbValue::Bool(b) => *b);
from_bb!(i64, BbValue::Int(i) => *i);
from_bb!(f64, BbValue::Float(f) => *f, BbValue::Int(i) => *i as f64);
from_bb!(Arc<str>, BbValue::Str(s) => s.clone());
from_bb!(Point2, BbValue::Point(p) => *p, BbValue::Pose(p) => p.position());
from_bb!(Pose2, BbValue::Pose(p) => *p);
from_bb!(GoalId, BbValue::Goal(g) => g.clone());
from_bb!(RobotId, BbValue::Robot(r) => r.clone());
from_bb!(Arc<Vec<Point2>>, BbValue::Points(p) => p.clone());
from_bb!(Arc<serde_json::Value>, BbValue::Params(p) => p.clone());

impl Binding {
    /// Reads the bound value.
    #[inline]
    pub fn get<T: FromBb>(&self, bb: &Blackboard) -> Option<T> {
        match self {
            Binding::Literal(v) => T::from_bb(v),
            Binding::Entry(k) => bb.get(*k).and_then(T::from_bb),
            Binding::Unset => None,
        }
    }

    /// Writes through the binding (only entries can be written).
    pub fn set(&self, bb: &mut Blackboard, value: BbValue) -> bool {
        match self {
            Binding::Entry(k) => bb.set(*k, value),
            _ => false,
        }
    }

    /// Erases the bound entry.
    pub fn clear(&self, bb: &mut Blackboard) {
        if let Binding::Entry(k) = self {
            bb.clear(*k);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn typed_set_rejects_wrong_types_and_widens_ints() {
        let mut bb = Blackboard::new();
        let k = bb.declare("speed", PortType::Float);
        assert!(!bb.set(k, BbValue::Str(Arc::from("fast"))));
        assert!(bb.set(k, BbValue::Int(2)));
        assert_eq!(bb.get(k), Some(&BbValue::Float(2.0)));
        assert_eq!(Binding::Entry(k).get::<f64>(&bb), Some(2.0));
        assert_eq!(Binding::Entry(k).get::<bool>(&bb), None);
    }

    #[test]
    fn events_live_for_two_ticks_unless_taken() {
        let mut bb = Blackboard::new();
        bb.raise_event("sync_complete");
        assert!(bb.has_event("sync_complete"));
        bb.end_tick();
        assert!(bb.has_event("sync_complete"));
        bb.end_tick();
        assert!(!bb.has_event("sync_complete"));
        bb.raise_event("x");
        assert!(bb.take_event("x"));
        assert!(!bb.has_event("x"));
    }
}
