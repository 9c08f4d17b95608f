//! The adapter sections of a mission (`comms:`, `sim:`; a robot's `ros2:`, `team_link:`): the
//! language knows their names and where they sit, and keeps each one as an opaque value; what is
//! inside (types, defaults, rules, JSON Schema) is their owner's, registered beside the node
//! types, the way a robot's `navigation:` is the robot layer's. So the language carries no
//! adapter settings and a lab's adapter adds a section without touching it.
//!
//! An owner checks its section twice, as the loader's stages run: [`SectionOwner::parse`] on the
//! span-carrying YAML (an unknown key or a wrong type is reported at its line and column with
//! its field path), then [`SectionOwner::check`] on the typed mission (ranges and rules across
//! sections). [`MissionSection`] and [`owner`] turn one serde type into an owner.

use std::path::PathBuf;
use std::sync::Arc;

use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use spomp_core::GeoPoint;

use crate::registry::{NodeCatalog, NodeRegistry};

use super::schema::{MissionFile, RobotSpec};
use super::yaml::{DeError, Node};

/// Where a section sits in a mission file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SectionPlace {
    /// At the top level (`comms:`, `sim:`).
    Mission,
    /// In each robot of `team:` (`ros2:`, `team_link:`).
    Robot,
}

/// The adapter sections the language has a place for: (name, where). A name not listed here is
/// an unknown key; one listed but with no owner registered is kept unchecked.
pub const SECTION_SLOTS: &[(&str, SectionPlace)] = &[
    ("comms", SectionPlace::Mission),
    ("sim", SectionPlace::Mission),
    ("ros2", SectionPlace::Robot),
    ("team_link", SectionPlace::Robot),
];

/// An adapter section as the mission holds it: the value written, unread by the language
/// (its owner reads it with [`MissionSection::of_mission`] / [`MissionSection::of_robot`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Section(pub serde_json::Value);

impl JsonSchema for Section {
    fn inline_schema() -> bool {
        true
    }
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "Section".into()
    }
    fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        // Replaced by the owner's schema in `json_schema::mission_schema`.
        schemars::json_schema!({})
    }
}

/// What a section's check sees besides the section: the typed mission and the folders files
/// may be in.
pub struct SectionContext<'a> {
    /// The whole typed mission (a section may check against the team, e.g. a fault's robot).
    pub mission: &'a MissionFile,
    /// The folders the mission's files may be in, the mission's own first.
    pub roots: &'a [PathBuf],
}

/// A problem in a section, at a field path relative to the section (`["topics", "odom"]`).
#[derive(Clone, Debug, PartialEq)]
pub struct SectionProblem {
    /// Field path inside the section (mapping keys and list indices).
    pub path: Vec<String>,
    /// What is wrong.
    pub message: String,
}

/// The owner of an adapter section: its schema and its checks.
pub trait SectionOwner: Send + Sync {
    /// The section's key (one of [`SECTION_SLOTS`]).
    fn name(&self) -> &'static str;
    /// The name of the section's definition in the mission schema's `$defs`.
    fn def_name(&self) -> String;
    /// The JSON Schema of the section (with its own `$defs`).
    fn schema(&self) -> serde_json::Value;
    /// The section's value when the mission leaves it out, for the schema's `default` (`None`:
    /// the section is optional and absent means none).
    fn default_value(&self) -> Option<serde_json::Value>;
    /// Reads the section from the YAML: an unknown key or a wrong type, with its place.
    fn parse(&self, node: &Node) -> Result<(), DeError>;
    /// Checks the section of a typed mission (`value`: the section as written, `None` when
    /// left out) against its rules.
    fn check(&self, value: Option<&serde_json::Value>, ctx: &SectionContext<'_>) -> Vec<SectionProblem>;
    /// Where the map frame's origin lies on the Earth by a robot's section (`value`), when the
    /// section gives the robot a GNSS reference (the ROS 2 section's `gps_origin`): the robot's
    /// georeference when the operating area has none.
    fn geo_reference(&self, value: &serde_json::Value) -> Option<GeoPoint> {
        let _ = value;
        None
    }
}

/// A section's settings type: serde reads it (`deny_unknown_fields`, defaults in the type),
/// schemars describes it, [`MissionSection::check`] holds its rules.
pub trait MissionSection: DeserializeOwned + JsonSchema + Default + Send + Sync + 'static {
    /// The section's key.
    const NAME: &'static str;
    /// Whether `null` is accepted for the section (as for an optional section left empty).
    const NULLABLE: bool = true;

    /// The section's rules: report each problem with `bad(path inside the section, message)`.
    fn check(&self, ctx: &SectionContext<'_>, bad: &mut dyn FnMut(&[&str], String));

    /// The GNSS reference this section gives its robot, if any (see
    /// [`SectionOwner::geo_reference`]).
    fn geo_reference(&self) -> Option<GeoPoint> {
        None
    }

    /// The section of a value as written (`None` or `null`: the defaults).
    fn from_value(value: Option<&serde_json::Value>) -> Result<Self, SectionError> {
        match value {
            None | Some(serde_json::Value::Null) => Ok(Self::default()),
            Some(v) => {
                Self::deserialize(v).map_err(|e| SectionError { section: Self::NAME.into(), message: e.to_string() })
            }
        }
    }

    /// The mission-level section of a mission (its defaults when left out).
    fn of_mission(mission: &MissionFile) -> Result<Self, SectionError> {
        Self::from_value(mission.section(Self::NAME))
    }

    /// A robot's section (its defaults when left out).
    fn of_robot(robot: &RobotSpec) -> Result<Self, SectionError> {
        Self::from_value(robot.section(Self::NAME))
            .map_err(|e| SectionError { section: format!("robot `{}` {}", robot.id, e.section), message: e.message })
    }

    /// Whether the mission gives this mission-level section.
    fn given_in(mission: &MissionFile) -> bool {
        mission.section(Self::NAME).is_some_and(|v| !v.is_null())
    }

    /// Whether the robot gives this section.
    fn given_for(robot: &RobotSpec) -> bool {
        robot.section(Self::NAME).is_some_and(|v| !v.is_null())
    }
}

/// A section that did not read (only for a mission that did not pass validation).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{section}: {message}")]
pub struct SectionError {
    /// Which section.
    pub section: String,
    /// What is wrong.
    pub message: String,
}

struct TypedOwner<T>(std::marker::PhantomData<fn() -> T>);

impl<T: MissionSection + Serialize> SectionOwner for TypedOwner<T> {
    fn name(&self) -> &'static str {
        T::NAME
    }

    fn def_name(&self) -> String {
        T::schema_name().into_owned()
    }

    fn schema(&self) -> serde_json::Value {
        serde_json::to_value(schemars::schema_for!(T)).unwrap_or_default()
    }

    fn default_value(&self) -> Option<serde_json::Value> {
        if T::NULLABLE { None } else { serde_json::to_value(T::default()).ok() }
    }

    fn parse(&self, node: &Node) -> Result<(), DeError> {
        if T::NULLABLE { node.deserialize::<Option<T>>().map(|_| ()) } else { node.deserialize::<T>().map(|_| ()) }
    }

    fn check(&self, value: Option<&serde_json::Value>, ctx: &SectionContext<'_>) -> Vec<SectionProblem> {
        let mut problems = Vec::new();
        match T::from_value(value) {
            Ok(section) => section.check(ctx, &mut |path, message| {
                problems.push(SectionProblem { path: path.iter().map(|s| s.to_string()).collect(), message })
            }),
            Err(e) => problems.push(SectionProblem { path: Vec::new(), message: e.message }),
        }
        problems
    }

    fn geo_reference(&self, value: &serde_json::Value) -> Option<GeoPoint> {
        T::from_value(Some(value)).ok()?.geo_reference()
    }
}

/// The owner of the section `T`.
pub fn owner<T: MissionSection + Serialize>() -> Arc<dyn SectionOwner> {
    Arc::new(TypedOwner::<T>(std::marker::PhantomData))
}

/// The registered owners, as the registry keeps them (one value per type).
#[derive(Clone, Default)]
struct SectionOwners(Vec<Arc<dyn SectionOwner>>);

impl<E> NodeRegistry<E> {
    /// Registers the owner of an adapter section, replacing an earlier owner of the same name.
    pub fn register_section(&mut self, owner: Arc<dyn SectionOwner>) {
        let mut owners = self.catalog().extension::<SectionOwners>().cloned().unwrap_or_default();
        owners.0.retain(|o| o.name() != owner.name());
        owners.0.push(owner);
        self.set_extension(owners);
    }
}

impl NodeCatalog {
    /// The owner of an adapter section, when one is registered.
    pub fn section_owner(&self, name: &str) -> Option<&dyn SectionOwner> {
        self.extension::<SectionOwners>().and_then(|o| o.0.iter().find(|o| o.name() == name)).map(|o| &**o)
    }

    /// The georeference a robot's sections give it (the first owner that gives one), for a
    /// robot over an operating area that has none.
    pub fn robot_geo_reference(&self, robot: &RobotSpec) -> Option<GeoPoint> {
        self.section_owners()
            .filter(|o| SECTION_SLOTS.contains(&(o.name(), SectionPlace::Robot)))
            .find_map(|o| o.geo_reference(robot.section(o.name())?))
    }

    /// Every registered section owner.
    pub fn section_owners(&self) -> impl Iterator<Item = &dyn SectionOwner> {
        self.extension::<SectionOwners>().into_iter().flat_map(|o| o.0.iter().map(|o| &**o))
    }
}
