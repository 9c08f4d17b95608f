//! Node-level parameter overrides and the tuning a driving node runs with.

#[allow(clippy::wildcard_imports)]
use super::*;
use crate::settings::merge;

// ---------------------------------------------------------------------------------------------
// Parameters

/// Node-level parameter overrides, checked when the node is built.
#[derive(Clone, Debug, Default)]
pub(super) struct Overrides {
    /// `local_planner` block (object with `local_goal` and/or `dwa`).
    pub(super) local: Option<Value>,
    /// `search` of the `global_planner` block.
    pub(super) search: Option<SearchParams>,
}

impl Overrides {
    pub(super) fn from_ports(p: &PortBindings, global: bool) -> Result<Self, NodeError> {
        let mut o = Overrides::default();
        if let Some(v) = params_literal(p, "local_planner")? {
            let bad = |m: String| NodeError::port("local_planner", m);
            let Some(obj) = v.as_object() else { return Err(bad("`local_planner` must be a mapping".into())) };
            if obj.contains_key("terrain") {
                return Err(bad("`local_planner.terrain` cannot be set per node: terrain analysis runs once per panorama for the whole robot; set it in the robot's navigation parameters".into()));
            }
            serde_json::from_value::<LocalPlannerParams>(v.clone())
                .map_err(|e| bad(format!("`local_planner`: {e}")))?
                .validate()
                .map_err(|e| bad(format!("`local_planner`: {e}")))?;
            o.local = Some(v);
        }
        if global && let Some(v) = params_literal(p, "global_planner")? {
            let bad = |m: String| NodeError::port("global_planner", m);
            let Some(obj) = v.as_object() else { return Err(bad("`global_planner` must be a mapping".into())) };
            if let Some(k) = obj.keys().find(|k| k.as_str() != "search") {
                return Err(bad(format!(
                    "`global_planner.{k}` cannot be set per node: the robot has one traversability graph, fed by every scan and shared by every node; set it in the robot's navigation parameters (only `search` is per node)"
                )));
            }
            if let Some(s) = obj.get("search") {
                let search: SearchParams =
                    serde_json::from_value(s.clone()).map_err(|e| bad(format!("`global_planner.search`: {e}")))?;
                if !(search.replan_cost_rise_ratio.is_finite() && search.replan_cost_rise_ratio >= 0.0) {
                    return Err(bad("`global_planner.search.replan_cost_rise_ratio` must be finite and >= 0".into()));
                }
                o.search = Some(search);
            }
        }
        Ok(o)
    }
}

pub(super) fn params_literal(p: &PortBindings, name: &'static str) -> Result<Option<Value>, NodeError> {
    match p.literal(name)? {
        None => match p.get(name)? {
            Binding::Unset => Ok(None),
            _ => Err(NodeError::port(
                name,
                format!("`{name}` must be written in the mission (a literal parameter block)"),
            )),
        },
        Some(BbValue::Params(v)) => Ok(Some((**v).clone())),
        Some(other) => {
            Err(NodeError::port(name, format!("`{name}` must be a mapping of parameters, not {:?}", other.port_type())))
        }
    }
}

/// What a driving node runs with: the robot's local-planner parameters with the node's
/// overrides, built once at the node's first start.
#[derive(Clone, Debug)]
pub(super) struct Tuning {
    pub(super) goal: LocalGoalParams,
    pub(super) dwa: Dwa,
    pub(super) replan_ratio: f64,
}

impl Tuning {
    pub(super) fn build(nav: &NavStack, overrides: &Overrides) -> Result<Self, String> {
        let mut local = nav.params().local.clone();
        if let Some(over) = &overrides.local {
            let mut base = serde_json::to_value(&local).map_err(|e| e.to_string())?;
            merge(&mut base, over);
            local = serde_json::from_value(base).map_err(|e| format!("local_planner: {e}"))?;
            local.validate().map_err(|e| format!("local_planner: {e}"))?;
        }
        let dwa = Dwa::new(local.dwa.clone()).map_err(|e| format!("local_planner: {e}"))?;
        let replan_ratio = overrides
            .search
            .as_ref()
            .map_or(nav.params().global.search.replan_cost_rise_ratio, |s| s.replan_cost_rise_ratio)
            .max(0.0);
        Ok(Tuning { goal: local.local_goal, dwa, replan_ratio })
    }
}
