//! Class names resolved against the operating area's class table, once, at setup.
//!
//! Skills name classes (`road`, `grass_sidewalk`, `vehicle`): the localizer's ground classes and
//! weights, the detector's goal class, the global planner's class order. A real site's class
//! table spells them its own way (`grass/sidewalk`, `Sidewalk`, `car`). A mission maps names in
//! `classes:`; names it does not map are looked up as they are, where spellings that differ only
//! in case and punctuation match ([`ClassTable::by_name`]). Every name a robot's skills will use
//! is resolved here to the table's own spelling, so that a skill never meets a name its table
//! lacks: what cannot be resolved is an error (the robot cannot do its job) or a warning (it can,
//! with less), each at the mission field that named it. `spomp validate` reports the same notes
//! at its world stage, before a run.

use std::collections::BTreeMap;

use spomp_behaviors::mission::MissionFile;
use spomp_behaviors::mission::schema::LocalizationMode;
use spomp_core::{ClassTable, RobotKind};
use spomp_localization::LocalizationParams;

/// One problem with a class name: where the mission names it, and what is wrong.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClassNote {
    /// The mission field, as a path: `team[1].localization.ground_classes`, `classes.vehicle`.
    pub field: String,
    /// What is wrong, naming the class and the table's classes.
    pub message: String,
    /// The robot cannot do its job as written (else it runs with less: a warning).
    pub error: bool,
}

/// The class names a robot's skills use, as its table spells them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RobotClasses {
    /// The detector's goal class (robots that detect goals).
    pub goal_class: Option<String>,
    /// The localizer's ground classes (cross-view UGVs).
    pub ground_classes: Vec<String>,
    /// The localizer's class weights (cross-view UGVs).
    pub class_weights: BTreeMap<String, f64>,
}

/// A mission's `classes:` mapping over a class table.
pub struct ClassNames<'a> {
    table: &'a ClassTable,
    mapping: &'a BTreeMap<String, String>,
}

impl<'a> ClassNames<'a> {
    /// The mission's names over `table`.
    pub fn new(mission: &'a MissionFile, table: &'a ClassTable) -> Self {
        ClassNames { table, mapping: &mission.classes }
    }

    /// The table's spelling of the class a mission or skill calls `name`, if the table has it.
    pub fn resolve(&self, name: &str) -> Option<String> {
        let wanted = self.mapping.get(name).map_or(name, String::as_str);
        self.table.by_name(wanted).map(|c| c.name.clone())
    }

    fn known(&self) -> String {
        self.table.names().join(", ")
    }

    /// The ground classes of robot `index` as the table spells them, whatever its localization
    /// mode: its `localization.ground_classes`, else the localizer's defaults; names the table
    /// lacks are left out (the notes of [`ClassNames::robot`] report them).
    pub fn ground_classes(&self, mission: &MissionFile, index: usize) -> Vec<String> {
        let listed =
            mission.team.get(index).and_then(|r| r.localization.as_ref()).and_then(|l| l.ground_classes.clone());
        let mut out: Vec<String> = Vec::new();
        for name in listed.unwrap_or_else(|| LocalizationParams::default().ground_classes) {
            if let Some(n) = self.resolve(&name).filter(|n| !out.contains(n)) {
                out.push(n);
            }
        }
        out
    }

    /// Problems with the mapping itself: every name it maps to must be in the table.
    pub fn mapping_notes(&self) -> Vec<ClassNote> {
        self.mapping
            .iter()
            .filter(|(_, to)| self.table.by_name(to).is_none())
            .map(|(from, to)| ClassNote {
                field: format!("classes.{from}"),
                message: format!(
                    "`{from}` is mapped to `{to}`, which the class table does not have (it has: {})",
                    self.known()
                ),
                error: true,
            })
            .collect()
    }

    /// The names robot `index` of `mission` will use, resolved, with a note for each name that
    /// does not resolve.
    pub fn robot(&self, mission: &MissionFile, index: usize) -> (RobotClasses, Vec<ClassNote>) {
        let mut out = RobotClasses::default();
        let mut notes = Vec::new();
        let Some(spec) = mission.team.get(index) else { return (out, notes) };
        let detects = matches!(spec.kind, RobotKind::Ugv | RobotKind::Basestation);
        if let Some(detect) = mission.goals.as_ref().and_then(|g| g.detect.as_ref()).filter(|_| detects) {
            match self.resolve(&detect.class) {
                Some(name) => out.goal_class = Some(name),
                None => notes.push(ClassNote {
                    field: "goals.detect.class".into(),
                    message: format!(
                        "the goal class `{}` is not in the class table (it has: {}); map it in `classes:`",
                        detect.class,
                        self.known()
                    ),
                    error: true,
                }),
            }
        }
        let cross_view = spec.kind == RobotKind::Ugv
            && spec.localization.as_ref().is_none_or(|l| l.mode == LocalizationMode::CrossView);
        if !cross_view {
            return (out, notes);
        }
        let defaults = LocalizationParams::default();
        let localization = spec.localization.as_ref();
        let ground_field = format!("team[{index}].localization.ground_classes");
        let ground = localization.and_then(|l| l.ground_classes.clone()).unwrap_or(defaults.ground_classes);
        let mut missing = Vec::new();
        for name in &ground {
            match self.resolve(name) {
                Some(n) if !out.ground_classes.contains(&n) => out.ground_classes.push(n),
                Some(_) => {}
                None => missing.push(name.as_str()),
            }
        }
        if out.ground_classes.is_empty() {
            notes.push(ClassNote {
                field: ground_field,
                message: format!(
                    "robot `{}` localizes on the ground classes {ground:?}, none of which the class table has (it \
                     has: {}): cross-view localization cannot work; map them in `classes:` or list the table's",
                    spec.id,
                    self.known()
                ),
                error: true,
            });
        } else if !missing.is_empty() {
            notes.push(ClassNote {
                field: ground_field,
                message: format!(
                    "robot `{}`: ground classes {missing:?} are not in the class table (it has: {}); localization \
                     uses {:?} only",
                    spec.id,
                    self.known(),
                    out.ground_classes
                ),
                error: false,
            });
        }
        let weights = localization.and_then(|l| l.class_weights.clone()).unwrap_or(defaults.class_weights);
        let mut dropped = Vec::new();
        for (name, weight) in &weights {
            match self.resolve(name) {
                Some(n) => {
                    out.class_weights.insert(n, *weight);
                }
                None => dropped.push(name.as_str()),
            }
        }
        if !dropped.is_empty() {
            notes.push(ClassNote {
                field: format!("team[{index}].localization.class_weights"),
                message: format!(
                    "robot `{}`: classes {dropped:?} that localization weighs are not in the class table (it has: \
                     {}); they count 0",
                    spec.id,
                    self.known()
                ),
                error: false,
            });
        }
        (out, notes)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

    use super::*;

    fn mission(extra: &str, localization: &str) -> MissionFile {
        let text = format!(
            "mission: names\n{extra}\
             team:\n  - {{ id: ugv1, kind: ugv, role: idle, priority: 1, start: {{ x_m: 5, y_m: 5 }}{localization} }}\n\
             goals: {{ detect: {{ class: vehicle }} }}\n\
             roles:\n  idle: {{ tree: {{ wait: {{ duration_s: 10 }} }} }}\n\
             complete_when: time_limit\ntime_limit_s: 10\n"
        );
        let loaded = spomp_behaviors::mission::load_mission_str(
            &text,
            std::path::Path::new("names.yaml"),
            &crate::registry(),
            &Default::default(),
        );
        assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
        loaded.mission.unwrap()
    }

    /// A site's own table: other spellings, a car class, no gravel.
    fn site_table() -> ClassTable {
        ClassTable::from_yaml(
            "classes:\n  - {index: 0, name: Road, rank: 0, color: [0,0,0]}\n  \
             - {index: 1, name: grass/sidewalk, rank: 2, color: [1,1,1]}\n  \
             - {index: 2, name: car, rank: 3, color: [2,2,2]}\n  \
             - {index: 3, name: building, rank: 5, color: [3,3,3]}\n",
        )
        .unwrap()
    }

    #[test]
    fn the_built_in_names_resolve_on_the_built_in_table_as_they_are() {
        let m = mission("", "");
        let table = ClassTable::default_table();
        let (classes, notes) = ClassNames::new(&m, &table).robot(&m, 0);
        assert!(notes.is_empty(), "{notes:?}");
        assert_eq!(classes.goal_class.as_deref(), Some("vehicle"));
        let defaults = LocalizationParams::default();
        assert_eq!(classes.ground_classes, defaults.ground_classes);
        assert_eq!(classes.class_weights, defaults.class_weights);
    }

    #[test]
    fn a_site_table_resolves_through_spellings_and_the_mapping_and_drops_what_it_lacks() {
        let m = mission("classes: { vehicle: car }\n", "");
        let table = site_table();
        let (classes, notes) = ClassNames::new(&m, &table).robot(&m, 0);
        assert_eq!(classes.goal_class.as_deref(), Some("car"));
        assert_eq!(classes.ground_classes, vec!["Road".to_string(), "grass/sidewalk".to_string()]);
        assert_eq!(classes.class_weights.get("grass/sidewalk"), Some(&0.75));
        assert_eq!(classes.class_weights.get("car"), Some(&0.5));
        // Gravel (ground) and vegetation, trunks, poles (weights) are not there: warnings only.
        assert_eq!(notes.len(), 2, "{notes:?}");
        assert!(notes.iter().all(|n| !n.error), "{notes:?}");
        assert_eq!(notes[0].field, "team[0].localization.ground_classes");
        assert!(notes[0].message.contains("gravel"), "{}", notes[0].message);
        assert_eq!(notes[1].field, "team[0].localization.class_weights");
    }

    #[test]
    fn an_unmapped_goal_class_a_bad_mapping_and_no_ground_class_are_errors() {
        let m = mission(
            "classes: { road: asphalt }\n",
            ", localization: { mode: cross_view, ground_classes: [road, gravel] }",
        );
        let table = site_table();
        let names = ClassNames::new(&m, &table);
        let (_, notes) = names.robot(&m, 0);
        let errors: Vec<&str> = notes.iter().filter(|n| n.error).map(|n| n.field.as_str()).collect();
        assert_eq!(errors, ["goals.detect.class", "team[0].localization.ground_classes"], "{notes:?}");
        let mapping = names.mapping_notes();
        assert_eq!(mapping.len(), 1);
        assert_eq!(mapping[0].field, "classes.road");
        assert!(mapping[0].message.contains("asphalt"), "{}", mapping[0].message);
    }

    #[test]
    fn ground_truth_robots_and_uavs_use_no_localizer_classes() {
        let m = mission("classes: { vehicle: car }\n", ", localization: { mode: ground_truth }");
        let table = site_table();
        let (classes, notes) = ClassNames::new(&m, &table).robot(&m, 0);
        assert!(notes.is_empty(), "{notes:?}");
        assert!(classes.ground_classes.is_empty() && classes.class_weights.is_empty());
    }
}
