//! A robot's navigation settings as a mission writes them: `navigation:` under a role, and
//! under a robot of the team to override its role's, field by field.
//!
//! ```yaml
//! roles:
//!   visitor:
//!     navigation:
//!       profile: simulation            # the paper's simulation values; default: robot
//!       terrain: { inflation_m: 0.9 }  # spomp-local-planner TerrainParams
//!       control: { max_speed_mps: 1.0 }  # DwaParams
//!       global_planner: { learning: off, graph_updates: off, sharing: all }
//!       watchdog: { stuck_timeout_s: 45, no_progress_timeout_s: 120 }
//! ```
//!
//! Every default and every validity rule is the skill's own: a profile is a named set of the
//! skills' constructors (`TerrainParams::simulation()`), the layers are applied over it, and the
//! result is checked with the skills' `validate()`. Problems carry the mission field path they
//! come from, so the mission language can point at the line.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value, json};
use spomp_global_planner::{GlobalPlannerParams, SharingMode};
use spomp_local_planner::{DwaParams, LocalGoalParams, LocalPlannerParams, TerrainParams};

use crate::runtime::NavParams;

/// Named sets of defaults the settings are applied over.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum NavigationProfile {
    /// The paper's real-robot values (terrain slope threshold 0.3, inflation 0.5 m).
    #[default]
    Robot,
    /// The paper's simulation values (slope threshold 0.25, inflation 0.75 m) with a 0.5 m
    /// reachability gap and no floor under a bin's safe range (both measured on the shipped team
    /// mission; `TerrainParams::simulation`): what the built-in simulator's robots were tuned
    /// with.
    Simulation,
}

/// When a driving node gives up as stuck.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct WatchdogParams {
    /// A driving node (`navigate_to`, `navigate_local`, `return_home`) that made less than 1 m
    /// of progress for this long is stuck (a node's own `stuck_timeout_s` port overrides it),
    /// seconds. A `navigate_to` or `return_home` whose robot has not moved at all (odometry
    /// within 0.25 m) for this long fails with `no_progress`.
    pub stuck_timeout_s: f64,
    /// A `navigate_to` or `return_home` whose robot has come neither 1 m nearer its target
    /// (straight line, the best distance so far) nor 1 m further along its path (the least path
    /// left so far; a longer route forced by an edge found blocked or costlier resets it, at most
    /// three times a drive) for this long fails with `no_progress`, however often it replanned:
    /// replans extend the time limit, this bound they do not (`navigate_to`'s own
    /// `no_progress_timeout_s` port overrides it), seconds.
    pub no_progress_timeout_s: f64,
}

impl Default for WatchdogParams {
    fn default() -> Self {
        WatchdogParams { stuck_timeout_s: 30.0, no_progress_timeout_s: 120.0 }
    }
}

impl WatchdogParams {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if !(self.stuck_timeout_s.is_finite() && self.stuck_timeout_s > 0.0 && self.stuck_timeout_s <= 86_400.0) {
            return Err(("stuck_timeout_s", "must be in (0, 86400] seconds".into()));
        }
        if !(self.no_progress_timeout_s.is_finite()
            && self.no_progress_timeout_s > 0.0
            && self.no_progress_timeout_s <= 86_400.0)
        {
            return Err(("no_progress_timeout_s", "must be in (0, 86400] seconds".into()));
        }
        Ok(())
    }
}

/// A UGV's navigation settings, resolved: the profile's values with the mission's layers over
/// them.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct NavigationSettings {
    /// The defaults everything else is applied over: `robot` (the paper's real-robot values) or
    /// `simulation` (its simulation values).
    pub profile: NavigationProfile,
    /// Terrain analysis of every panorama (spomp-local-planner `TerrainParams`).
    pub terrain: TerrainParams,
    /// Local goal selection in the safe region.
    pub local_goal: LocalGoalParams,
    /// The DWA controller's limits and weights.
    pub control: DwaParams,
    /// The traversability graph, learned traversability, experience from scans, scan sharing
    /// and search (spomp-global-planner). Shorthands: `learning: on|off`,
    /// `graph_updates: on|off` (for `experience.graph_updates`), `sharing: none|downsampled|all`.
    pub global_planner: GlobalPlannerParams,
    /// When driving nodes give up as stuck.
    pub watchdog: WatchdogParams,
}

/// A setting that cannot be used, with the path of the field inside `navigation:`.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("navigation.{}: {message}", path.join("."))]
pub struct SettingsError {
    /// Field path inside the `navigation:` section (`["terrain", "inflation_m"]`).
    pub path: Vec<String>,
    /// What is wrong.
    pub message: String,
    /// Which layer the value came from (index into the layers given to
    /// [`NavigationSettings::resolve`]); `None`: a value of the profile.
    pub layer: Option<usize>,
}

impl NavigationSettings {
    /// The values of a profile.
    pub fn profile(profile: NavigationProfile) -> Self {
        let local = match profile {
            NavigationProfile::Robot => LocalPlannerParams::default(),
            NavigationProfile::Simulation => LocalPlannerParams::simulation(),
        };
        NavigationSettings {
            profile,
            terrain: local.terrain,
            local_goal: local.local_goal,
            control: local.dwa,
            global_planner: GlobalPlannerParams::default(),
            watchdog: WatchdogParams::default(),
        }
    }

    /// Resolves `navigation:` layers (a role's, then a robot's), each a mapping as written in the
    /// mission: the profile named by the last layer that names one, every layer applied over it
    /// field by field, then every value checked by its skill.
    pub fn resolve(layers: &[&Value]) -> Result<Self, SettingsError> {
        let mut normalized = Vec::with_capacity(layers.len());
        for (i, layer) in layers.iter().enumerate() {
            let layer = normalize(layer).map_err(|(path, message)| SettingsError { path, message, layer: Some(i) })?;
            // Each layer alone must be well formed: unknown keys and wrong types are reported
            // where they were written.
            if let Err(e) = serde_path_to_error::deserialize::<_, NavigationSettings>(&layer) {
                return Err(SettingsError {
                    path: path_segments(e.path()),
                    message: e.inner().to_string(),
                    layer: Some(i),
                });
            }
            normalized.push(layer);
        }
        let profile = normalized
            .iter()
            .rev()
            .find_map(|l| l.get("profile"))
            .and_then(|p| serde_json::from_value(p.clone()).ok())
            .unwrap_or_default();
        let mut merged =
            serde_json::to_value(Self::profile(profile)).map_err(|e| SettingsError::whole(e.to_string()))?;
        for layer in &normalized {
            merge(&mut merged, layer);
        }
        let settings: NavigationSettings = serde_path_to_error::deserialize(&merged).map_err(|e| SettingsError {
            path: path_segments(e.path()),
            message: e.inner().to_string(),
            layer: None,
        })?;
        settings.validate().map_err(|(path, message)| {
            let layer = normalized.iter().rposition(|l| lookup(l, &path).is_some());
            SettingsError { path, message, layer }
        })?;
        Ok(settings)
    }

    /// Checks every value with its skill's own rules; the error names the field path.
    pub fn validate(&self) -> Result<(), (Vec<String>, String)> {
        let at = |section: &str, field: &str| vec![section.to_string(), field.to_string()];
        self.terrain.validate().map_err(|e| (at("terrain", e.name), e.reason.to_string()))?;
        self.local_goal.validate().map_err(|e| (at("local_goal", e.name), e.reason.to_string()))?;
        self.control.validate().map_err(|e| (at("control", e.name), e.reason.to_string()))?;
        self.global_planner.validate().map_err(|e| match e {
            spomp_global_planner::SetupError::InvalidParameter { name, reason } => {
                let mut path = vec!["global_planner".to_string()];
                path.extend(name.split('.').map(str::to_string));
                (path, reason)
            }
            other => (vec!["global_planner".to_string()], other.to_string()),
        })?;
        self.watchdog.validate().map_err(|(field, reason)| (at("watchdog", field), reason))?;
        Ok(())
    }

    /// The navigation stack's parameters.
    pub fn into_nav_params(self) -> NavParams {
        NavParams {
            local: LocalPlannerParams { terrain: self.terrain, local_goal: self.local_goal, dwa: self.control },
            global: self.global_planner,
            watchdog: self.watchdog,
        }
    }

    /// The JSON Schema of a `navigation:` section, shorthands included (for `spomp schema`).
    pub fn json_schema() -> Value {
        let schema = schemars::schema_for!(NavigationSettings);
        let mut v = serde_json::to_value(schema).unwrap_or(Value::Null);
        // The global planner's shorthands, beside the full forms.
        let switch = json!({ "anyOf": [ { "type": "boolean" }, { "enum": ["on", "off"] } ] });
        if let Some(gp) = v.pointer_mut("/$defs/GlobalPlannerParams/properties").and_then(Value::as_object_mut) {
            for key in ["learning", "sharing"] {
                if let Some(full) = gp.get(key).cloned() {
                    let short = if key == "learning" {
                        switch.clone()
                    } else {
                        json!({ "enum": ["none", "downsampled", "all"] })
                    };
                    gp.insert(key.into(), json!({ "anyOf": [short, full] }));
                }
            }
            gp.insert(
                "graph_updates".into(),
                json!({ "description": "Shorthand for `experience.graph_updates`: edge updates from scans on or off.", "anyOf": switch["anyOf"] }),
            );
        }
        v
    }
}

impl SettingsError {
    fn whole(message: String) -> Self {
        SettingsError { path: Vec::new(), message, layer: None }
    }
}

/// `on`/`off`/`true`/`false` (or a YAML boolean) as a boolean.
fn switch(v: &Value) -> Option<bool> {
    match v {
        Value::Bool(b) => Some(*b),
        Value::String(s) => match s.as_str() {
            "on" | "true" => Some(true),
            "off" | "false" => Some(false),
            _ => None,
        },
        _ => None,
    }
}

/// A layer with the global planner's shorthands expanded into the full forms.
fn normalize(layer: &Value) -> Result<Value, (Vec<String>, String)> {
    let Some(obj) = layer.as_object() else {
        return Err((Vec::new(), format!("expected a mapping of navigation settings, found {}", kind(layer))));
    };
    let mut out = obj.clone();
    if let Some(Value::Object(gp)) = out.get_mut("global_planner") {
        let at = |k: &str| vec!["global_planner".to_string(), k.to_string()];
        if let Some(v) = gp.get("learning").filter(|v| !v.is_object()) {
            let on = switch(v).ok_or_else(|| (at("learning"), format!("expected on, off or a mapping, found {v}")))?;
            gp.insert("learning".into(), json!({ "enabled": on }));
        }
        if let Some(v) = gp.remove("graph_updates") {
            let on = switch(&v).ok_or_else(|| (at("graph_updates"), format!("expected on or off, found {v}")))?;
            let experience = gp.entry("experience").or_insert_with(|| Value::Object(Map::new()));
            match experience.as_object_mut() {
                Some(e) => {
                    e.insert("graph_updates".into(), Value::Bool(on));
                }
                None => return Err((at("experience"), "expected a mapping".into())),
            }
        }
        if let Some(v) = gp.get("sharing").filter(|v| v.is_string()) {
            let mode: SharingMode = serde_json::from_value(v.clone())
                .map_err(|_| (at("sharing"), format!("expected none, downsampled, all or a mapping, found {v}")))?;
            gp.insert("sharing".into(), json!({ "mode": mode }));
        }
    }
    Ok(Value::Object(out))
}

fn kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "nothing",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "a mapping",
    }
}

/// Merges `over` into `base`: mappings field by field, anything else replaced. The one JSON
/// patcher of the workspace: a role's `navigation:` under a robot's, a node's parameter block
/// over the robot's parameters, an experiment configuration over its base mission.
pub fn merge(base: &mut Value, over: &Value) {
    match (base, over) {
        (Value::Object(b), Value::Object(o)) => {
            for (k, v) in o {
                match b.get_mut(k) {
                    Some(slot) => merge(slot, v),
                    None => {
                        b.insert(k.clone(), v.clone());
                    }
                }
            }
        }
        (b, o) => *b = o.clone(),
    }
}

fn lookup<'v>(v: &'v Value, path: &[String]) -> Option<&'v Value> {
    path.iter().try_fold(v, |v, seg| v.get(seg.as_str()))
}

fn path_segments(path: &serde_path_to_error::Path) -> Vec<String> {
    path.iter()
        .filter_map(|seg| match seg {
            serde_path_to_error::Segment::Map { key } => Some(key.clone()),
            serde_path_to_error::Segment::Seq { index } => Some(index.to_string()),
            serde_path_to_error::Segment::Enum { variant } => Some(variant.clone()),
            serde_path_to_error::Segment::Unknown => None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn a_profile_is_the_skills_own_constructor() {
        let s = NavigationSettings::resolve(&[&json!({ "profile": "simulation" })]).unwrap();
        assert_eq!(s.terrain, TerrainParams::simulation());
        let r = NavigationSettings::resolve(&[]).unwrap();
        assert_eq!(r.terrain, TerrainParams::default());
    }

    #[test]
    fn a_robot_layer_overrides_its_roles_field_by_field() {
        let role = json!({ "profile": "simulation", "terrain": { "inflation_m": 0.9, "slope_threshold": 0.2 } });
        let robot = json!({ "terrain": { "inflation_m": 1.0 } });
        let s = NavigationSettings::resolve(&[&role, &robot]).unwrap();
        assert_eq!(s.terrain.inflation_m, 1.0);
        assert_eq!(s.terrain.slope_threshold, 0.2);
        assert_eq!(s.terrain.max_obstacle_distance_m, TerrainParams::simulation().max_obstacle_distance_m);
    }

    #[test]
    fn shorthands_switch_the_papers_ablations() {
        let s = NavigationSettings::resolve(&[&json!({
            "global_planner": { "learning": "off", "graph_updates": false, "sharing": "all" }
        })])
        .unwrap();
        assert!(!s.global_planner.learning.enabled);
        assert!(!s.global_planner.experience.graph_updates);
        assert_eq!(s.global_planner.sharing.mode, SharingMode::All);
    }

    #[test]
    fn a_bad_value_names_its_field_and_the_layer_it_came_from() {
        let role = json!({ "terrain": { "inflation_m": 0.5 } });
        let robot = json!({ "terrain": { "inflation_m": -1.0 } });
        let e = NavigationSettings::resolve(&[&role, &robot]).unwrap_err();
        assert_eq!(e.path, vec!["terrain", "inflation_m"]);
        assert_eq!(e.layer, Some(1));
        let e = NavigationSettings::resolve(&[&json!({ "control": { "max_speed_mps": "fast" } })]).unwrap_err();
        assert_eq!(e.path, vec!["control", "max_speed_mps"]);
        let e = NavigationSettings::resolve(&[&json!({ "terrain": { "inflaton_m": 1 } })]).unwrap_err();
        assert!(e.message.contains("inflaton_m"), "{e}");
        let e = NavigationSettings::resolve(&[&json!({ "global_planner": { "learning": "maybe" } })]).unwrap_err();
        assert_eq!(e.path, vec!["global_planner", "learning"]);
    }
}
