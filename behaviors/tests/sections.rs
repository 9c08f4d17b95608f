//! Adapter sections of a mission (`comms:`, `sim:`, a robot's `ros2:` and `team_link:`) are
//! opaque to the language and checked by the owner registered for them: its unknown keys and
//! its rules are reported at their line and column, its schema is the mission schema's, and the
//! owner reads its section back typed.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::Path;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_behaviors::mission::json_schema::mission_schema;
use spomp_behaviors::mission::{LoadOptions, LoadedMission, MissionSection, SectionContext, load_mission_str, owner};
use spomp_behaviors::{NodeRegistry, engine_registry};

/// A lab's radio settings, owning `comms:`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
struct LabRadio {
    /// Range, metres.
    #[serde(default = "default_range")]
    range_m: f64,
}

fn default_range() -> f64 {
    40.0
}

impl Default for LabRadio {
    fn default() -> Self {
        LabRadio { range_m: default_range() }
    }
}

impl MissionSection for LabRadio {
    const NAME: &'static str = "comms";
    fn check(&self, _: &SectionContext<'_>, bad: &mut dyn FnMut(&[&str], String)) {
        if self.range_m < 0.0 {
            bad(&["range_m"], format!("a range cannot be negative, found {}", self.range_m));
        }
    }
}

/// A lab's per-robot link settings, owning `team_link:`; it needs the team to check itself.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
struct LabLink {
    /// The robot this one relays through.
    #[serde(default)]
    relay: Option<String>,
}

impl MissionSection for LabLink {
    const NAME: &'static str = "team_link";
    fn check(&self, ctx: &SectionContext<'_>, bad: &mut dyn FnMut(&[&str], String)) {
        if let Some(r) = &self.relay
            && !ctx.mission.team.iter().any(|t| &t.id == r)
        {
            bad(&["relay"], format!("no robot `{r}` in the team"));
        }
    }
}

fn mission(comms: &str, link: &str) -> String {
    format!(
        "mission: m\nteam:\n  - id: b\n    kind: basestation\n    role: r\n    start: {{ x_m: 0, y_m: 0 }}\n{link}\
         roles:\n  r:\n    tree:\n      wait: {{ duration_s: 1 }}\ntime_limit_s: 10\n{comms}"
    )
}

fn load(text: &str, registry: &NodeRegistry<()>) -> LoadedMission {
    load_mission_str(text, Path::new("m.yaml"), registry, &LoadOptions::default())
}

fn lab_registry() -> NodeRegistry<()> {
    let mut r = engine_registry::<()>();
    r.register_section(owner::<LabRadio>());
    r.register_section(owner::<LabLink>());
    r
}

#[test]
fn without_an_owner_a_section_is_kept_as_written_and_unchecked() {
    let text = mission("comms: { anything: [1, 2] }\n", "    team_link: { whatever: true }\n");
    let loaded = load(&text, &engine_registry::<()>());
    assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
    let m = loaded.mission.unwrap();
    assert_eq!(m.section("comms").unwrap()["anything"][1], 2);
    assert_eq!(m.team[0].section("team_link").unwrap()["whatever"], true);
    // A name with no slot is still an unknown key.
    let loaded = load(&mission("radio: {}\n", ""), &engine_registry::<()>());
    assert!(loaded.diagnostics.iter().any(|d| d.message.contains("unknown key `radio`")), "{:#?}", loaded.diagnostics);
}

#[test]
fn the_owner_reports_unknown_keys_and_broken_rules_at_their_place() {
    let r = lab_registry();
    let loaded = load(&mission("comms:\n  rang_m: 3\n", ""), &r);
    let d = loaded.diagnostics.iter().find(|d| d.node_path == "comms.rang_m").expect("unknown key reported");
    assert_eq!((d.line, d.column), (13, 3));
    assert!(d.message.contains("unknown field `rang_m`"), "{}", d.message);

    let loaded = load(&mission("comms:\n  range_m: -1\n", ""), &r);
    let d = loaded.diagnostics.iter().find(|d| d.node_path == "comms.range_m").expect("rule reported");
    assert_eq!((d.line, d.column), (13, 12));
    assert!(d.message.contains("cannot be negative"), "{}", d.message);

    let loaded = load(&mission("", "    team_link: { relay: ugv9 }\n"), &r);
    let d = loaded.diagnostics.iter().find(|d| d.node_path == "team.0.team_link.relay").expect("robot rule reported");
    assert_eq!(d.line, 7);
    assert!(d.message.contains("no robot `ugv9`"), "{}", d.message);
    let loaded = load(&mission("", "    team_link: { relays: b }\n"), &r);
    assert!(
        loaded.diagnostics.iter().any(|d| d.node_path == "team[0].team_link.relays" && d.line == 7),
        "{:#?}",
        loaded.diagnostics
    );
}

#[test]
fn the_owner_reads_its_section_back_with_its_defaults() {
    let r = lab_registry();
    let loaded = load(&mission("comms: { range_m: 12 }\n", ""), &r);
    assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
    assert_eq!(LabRadio::of_mission(loaded.mission.as_ref().unwrap()).unwrap(), LabRadio { range_m: 12.0 });
    let loaded = load(&mission("", ""), &r);
    let m = loaded.mission.unwrap();
    assert_eq!(LabRadio::of_mission(&m).unwrap(), LabRadio::default(), "left out: the owner's defaults");
    assert!(!LabLink::given_for(&m.team[0]));
}

#[test]
fn the_mission_schema_takes_each_section_from_its_owner() {
    let bare = mission_schema(engine_registry::<()>().catalog());
    assert!(bare["$defs"].get("LabRadio").is_none());
    let schema = mission_schema(lab_registry().catalog());
    let comms = &schema["properties"]["comms"];
    assert_eq!(comms["anyOf"][0]["$ref"], "#/$defs/LabRadio", "{comms:#}");
    assert_eq!(schema["$defs"]["LabRadio"]["properties"]["range_m"]["default"], 40.0);
    assert_eq!(schema["$defs"]["LabRadio"]["additionalProperties"], false);
    let link = &schema["$defs"]["RobotSpec"]["properties"]["team_link"];
    assert_eq!(link["anyOf"][0]["$ref"], "#/$defs/LabLink", "{link:#}");
}
