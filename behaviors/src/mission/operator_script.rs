//! `sim.operator:` — operator commands scripted at simulated times (issue 37), so missions with
//! an operator in the loop are tested and studied like any other. The simulator issues each
//! one from an operator member of the team that reaches the robots over the modelled radio
//! (see the simulator's `operator` module); this module is only the mission-language part:
//! the entries, their fields and their checks.
//!
//! ```yaml
//! sim:
//!   operator:
//!     - { at_s: 300, goal_add: { at: [120, 80], priority: 1, name: depot } }
//!     - { at_s: 360, goal_priority: { goal: depot, priority: 3 } }
//!     - { at_s: 420, recall: ugv2 }
//!     - { at_s: 500, hold: all }
//!     - { at_s: 530, resume: all }
//!     - { at_s: 600, goal_cancel: { at: [200, 40] } }
//! ```

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// One scripted operator command: when, and exactly one action.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ScriptedCommand {
    /// When the operator issues it, simulated seconds from the start.
    pub at_s: f64,
    /// Add a goal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_add: Option<ScriptedGoalAdd>,
    /// Cancel a goal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_cancel: Option<ScriptedGoalRef>,
    /// Change a goal's priority.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_priority: Option<ScriptedGoalPriority>,
    /// Recall a robot (its id) or every robot (`all`) home.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recall: Option<String>,
    /// Hold a robot (its id) or every robot (`all`) where it is.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold: Option<String>,
    /// Lift a hold or recall of a robot (its id) or of every robot (`all`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resume: Option<String>,
}

/// `goal_add`: a goal at a map position.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ScriptedGoalAdd {
    /// Map-frame position `[x, y]`, metres.
    pub at: [f64; 2],
    /// Priority: 0 is an ordinary goal, higher is taken first, lower after the others.
    #[serde(default)]
    pub priority: i32,
    /// A name later commands may address it by.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// What is there (for the log).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub class: Option<String>,
}

/// Which goal a command addresses: by `goal` (an id such as `mission/2`, or a name given with
/// `goal_add`) or by `at` (the goal within the deconfliction radius of that point); exactly one.
/// A goal the operator does not know yet when the command is due is addressed as soon as it
/// learns of it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ScriptedGoalRef {
    /// Goal id or name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal: Option<String>,
    /// A map-frame point `[x, y]` within the deconfliction radius of the goal, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<[f64; 2]>,
}

/// `goal_priority`: a goal (as in [`ScriptedGoalRef`]) and its new priority.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ScriptedGoalPriority {
    /// Goal id or name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal: Option<String>,
    /// A map-frame point `[x, y]` within the deconfliction radius of the goal, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<[f64; 2]>,
    /// The new priority (0 ordinary, higher first).
    pub priority: i32,
}

impl ScriptedGoalPriority {
    /// The goal it addresses.
    pub fn goal_ref(&self) -> ScriptedGoalRef {
        ScriptedGoalRef { goal: self.goal.clone(), at: self.at }
    }
}

/// Longest goal name or class, characters (the team state's limit on operator text).
const MAX_TEXT: usize = 128;

impl ScriptedGoalRef {
    fn check(&self) -> Result<(), String> {
        match (&self.goal, &self.at) {
            (Some(_), Some(_)) | (None, None) => Err("give exactly one of `goal` (id or name) and `at`".into()),
            (_, Some(p)) if !(p[0].is_finite() && p[1].is_finite()) => Err("`at` must be finite".into()),
            (Some(g), _) if g.is_empty() => Err("`goal` is empty".into()),
            _ => Ok(()),
        }
    }
}

impl ScriptedCommand {
    /// The action's field name (`goal_add`, …), or an error unless exactly one is given.
    pub fn action_name(&self) -> Result<&'static str, String> {
        let given: Vec<&'static str> = [
            ("goal_add", self.goal_add.is_some()),
            ("goal_cancel", self.goal_cancel.is_some()),
            ("goal_priority", self.goal_priority.is_some()),
            ("recall", self.recall.is_some()),
            ("hold", self.hold.is_some()),
            ("resume", self.resume.is_some()),
        ]
        .into_iter()
        .filter_map(|(name, set)| set.then_some(name))
        .collect();
        match given.as_slice() {
            [one] => Ok(one),
            [] => Err("no action: give one of goal_add, goal_cancel, goal_priority, recall, hold, resume".into()),
            many => Err(format!("one action per entry, found {}", many.join(", "))),
        }
    }

    /// Checks the entry against the team's robot ids: time, one action, its fields, its target.
    /// Returns the field (relative to the entry) and what is wrong.
    pub fn check(&self, robots: &[&str]) -> Result<(), (String, String)> {
        if !(self.at_s.is_finite() && self.at_s >= 0.0) {
            return Err(("at_s".into(), format!("must be finite and ≥ 0, found {}", self.at_s)));
        }
        let action = self.action_name().map_err(|e| (String::new(), e))?;
        let fail = |why: String| Err((action.to_string(), why));
        if let Some(add) = &self.goal_add {
            if !(add.at[0].is_finite() && add.at[1].is_finite()) {
                return fail("`at` must be finite".into());
            }
            for (what, text) in [("name", &add.name), ("class", &add.class)] {
                if text.as_ref().is_some_and(|t| t.is_empty() || t.chars().count() > MAX_TEXT) {
                    return fail(format!("`{what}` must be 1 to {MAX_TEXT} characters"));
                }
            }
        }
        if let Some(r) = &self.goal_cancel {
            r.check().or_else(fail)?;
        }
        if let Some(p) = &self.goal_priority {
            p.goal_ref().check().or_else(fail)?;
        }
        for target in [&self.recall, &self.hold, &self.resume].into_iter().flatten() {
            if target != "all" && !robots.contains(&target.as_str()) {
                return fail(format!("`{target}` is not a robot of the team (ids: {}; or `all`)", robots.join(", ")));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(yaml: &str) -> ScriptedCommand {
        serde_saphyr::from_str(yaml).unwrap()
    }

    #[test]
    fn entries_check_their_one_action_and_its_target() {
        let robots = ["ugv1", "ugv2"];
        assert!(entry("{at_s: 300, goal_add: {at: [1, 2], priority: 1}}").check(&robots).is_ok());
        assert!(entry("{at_s: 420, recall: ugv2}").check(&robots).is_ok());
        assert!(entry("{at_s: 420, hold: all}").check(&robots).is_ok());
        let bad = |yaml: &str| entry(yaml).check(&robots).unwrap_err();
        assert_eq!(bad("{at_s: 1, recall: ugv9}").0, "recall");
        assert!(bad("{at_s: 1}").1.contains("no action"));
        assert!(bad("{at_s: 1, hold: all, resume: all}").1.contains("one action"));
        assert_eq!(bad("{at_s: -1, hold: all}").0, "at_s");
        assert!(bad("{at_s: 1, goal_cancel: {}}").1.contains("exactly one"));
        assert!(bad("{at_s: 1, goal_priority: {goal: a, at: [1, 1], priority: 2}}").1.contains("exactly one"));
        assert!(serde_saphyr::from_str::<ScriptedCommand>("{at_s: 1, recal: ugv1}").is_err(), "unknown field");
    }
}
