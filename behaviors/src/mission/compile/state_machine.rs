//! State machines: states, reachability, transitions on outcomes, timers and events.

use std::collections::{HashMap, VecDeque};

#[allow(clippy::wildcard_imports)]
use super::*;

impl<'a> Compiler<'a> {
    pub(super) fn state_machine(
        &mut self,
        spec: &NodeTypeSpec,
        key: &Key,
        body: &Node,
        file: FileId,
        path: String,
    ) -> Option<Ir> {
        self.params(spec, key, body, file, &path, &["states", "name"])?;
        let Some(states_node) = body.get("states") else {
            self.err(
                file,
                key.loc,
                &path,
                Stage::Schema,
                "`state_machine` needs `states:` (a mapping of state names to states)",
            );
            return None;
        };
        let Some(state_entries) = states_node.as_map() else {
            self.err(
                file,
                states_node.loc,
                &path,
                Stage::Schema,
                format!("`states` must be a mapping of state names to states, found {}", states_node.value.kind()),
            );
            return None;
        };
        if state_entries.is_empty() {
            self.err(file, states_node.loc, &path, Stage::Schema, "`states` is empty");
            return None;
        }
        let index: HashMap<&str, usize> =
            state_entries.iter().enumerate().map(|(i, (k, _))| (k.name.as_str(), i)).collect();
        let names: Vec<&str> = state_entries.iter().map(|(k, _)| k.name.as_str()).collect();
        let mut ok = true;
        let initial = match body.get("initial") {
            None => {
                self.err(
                    file,
                    key.loc,
                    &path,
                    Stage::Schema,
                    "missing port `initial` of `state_machine` (the first state)",
                );
                return None;
            }
            Some(n) => match n.as_str() {
                Some(s) => match index.get(s) {
                    Some(&i) => i,
                    None => {
                        self.err(
                            file,
                            n.loc,
                            &path,
                            Stage::Wiring,
                            format!("initial state `{s}` is not defined; states are: {}", names.join(", ")),
                        );
                        return None;
                    }
                },
                None => {
                    self.err(
                        file,
                        n.loc,
                        &path,
                        Stage::Schema,
                        format!("`initial` must be a state name, found {}", n.value.kind()),
                    );
                    return None;
                }
            },
        };
        let mut states = Vec::new();
        for (k, snode) in state_entries {
            let spath = format!("{path}.{}", k.name);
            let mut st = IrState { name: k.name.clone(), run: None, transitions: Vec::new(), terminal: None };
            let Some(fields) = snode.as_map() else {
                self.err(
                    file,
                    snode.loc,
                    &spath,
                    Stage::Schema,
                    format!(
                        "a state must be a mapping with `run`, `transitions` or `terminal`, found {}",
                        snode.value.kind()
                    ),
                );
                ok = false;
                continue;
            };
            for (fk, fv) in fields {
                match fk.name.as_str() {
                    "run" => match self.compile(fv, file, &spath) {
                        Some(ir) => st.run = Some(ir),
                        None => ok = false,
                    },
                    "terminal" => match fv.as_str() {
                        Some("success") => st.terminal = Some(Status::Success),
                        Some("failure") => st.terminal = Some(Status::Failure),
                        _ => {
                            self.err(file, fv.loc, &spath, Stage::Schema, "`terminal` must be `success` or `failure`");
                            ok = false;
                        }
                    },
                    "transitions" => {
                        let Some(list) = fv.as_seq() else {
                            self.err(
                                file,
                                fv.loc,
                                &spath,
                                Stage::Schema,
                                format!("`transitions` must be a list, found {}", fv.value.kind()),
                            );
                            ok = false;
                            continue;
                        };
                        for (ti, t) in list.iter().enumerate() {
                            let tpath = format!("{spath}.transitions[{ti}]");
                            match self.transition(t, file, &tpath, &index, &names) {
                                Some(tr) => st.transitions.push(tr),
                                None => ok = false,
                            }
                        }
                    }
                    "description" => {}
                    other => {
                        self.err(
                            file,
                            fk.loc,
                            &spath,
                            Stage::Schema,
                            format!(
                                "unknown key `{other}` in a state; expected run, transitions, terminal or description"
                            ),
                        );
                        ok = false;
                    }
                }
            }
            if st.terminal.is_some() && (st.run.is_some() || !st.transitions.is_empty()) {
                self.err(
                    file,
                    k.loc,
                    &spath,
                    Stage::Wiring,
                    "a terminal state ends the machine: it cannot have `run` or `transitions`",
                );
                ok = false;
            }
            if st.terminal.is_none()
                && st.run.is_none()
                && !st.transitions.iter().any(|(t, _)| matches!(t, Trigger::Timer(_) | Trigger::Event(_)))
                && fields.iter().all(|(fk, _)| fk.name != "run")
            {
                self.err(file, k.loc, &spath, Stage::Wiring, "a state without `run` must have a timer or event transition, or be `terminal`; otherwise it waits forever");
                ok = false;
            }
            states.push(st);
        }
        if ok {
            // Every state must be reachable from the initial one.
            let mut seen = vec![false; states.len()];
            let mut queue = VecDeque::from([initial]);
            seen[initial] = true;
            while let Some(s) = queue.pop_front() {
                for &(_, t) in &states[s].transitions {
                    if !seen[t] {
                        seen[t] = true;
                        queue.push_back(t);
                    }
                }
            }
            for (i, (k, _)) in state_entries.iter().enumerate() {
                if !seen[i] {
                    self.err(
                        file,
                        k.loc,
                        &format!("{path}.{}", k.name),
                        Stage::Wiring,
                        format!(
                            "state `{}` is unreachable: no transition from `{}` leads to it",
                            k.name, names[initial]
                        ),
                    );
                    ok = false;
                }
            }
        }
        ok.then(|| Ir {
            type_name: spec.name.to_string(),
            path,
            loc: key.loc,
            file,
            kind: IrKind::StateMachine { states, initial },
        })
    }

    pub(super) fn transition(
        &mut self,
        t: &Node,
        file: FileId,
        path: &str,
        index: &HashMap<&str, usize>,
        names: &[&str],
    ) -> Option<(Trigger, usize)> {
        let Some(fields) = t.as_map() else {
            self.err(
                file,
                t.loc,
                path,
                Stage::Schema,
                format!("a transition must be a mapping like `{{on: success, to: next}}`, found {}", t.value.kind()),
            );
            return None;
        };
        for (k, _) in fields {
            if !["on", "to", "after_s", "event"].contains(&k.name.as_str()) {
                self.err(
                    file,
                    k.loc,
                    path,
                    Stage::Schema,
                    format!("unknown key `{}` in a transition; expected on, to, after_s or event", k.name),
                );
                return None;
            }
        }
        let on = t.get("on").and_then(Node::as_str);
        let trigger = match on {
            Some("success") => Trigger::Success,
            Some("failure") => Trigger::Failure,
            Some("timer") => match t.get("after_s") {
                Some(v) => match v.as_f64() {
                    Some(s) => match crate::mission::limits::duration_from_secs(s) {
                        Ok(d) => Trigger::Timer(d),
                        Err(e) => {
                            self.err(file, v.loc, path, Stage::Schema, format!("`after_s`: {e}"));
                            return None;
                        }
                    },
                    None => {
                        self.err(
                            file,
                            v.loc,
                            path,
                            Stage::Schema,
                            format!("`after_s` must be a number of seconds, found {}", v.value.kind()),
                        );
                        return None;
                    }
                },
                None => {
                    self.err(file, t.loc, path, Stage::Schema, "a timer transition needs `after_s`");
                    return None;
                }
            },
            Some("event") => match t.get("event").and_then(Node::as_str) {
                Some(e) => Trigger::Event(e.to_string()),
                None => {
                    self.err(file, t.loc, path, Stage::Schema, "an event transition needs `event: <name>`");
                    return None;
                }
            },
            Some(other) => {
                let loc = t.get("on").map_or(t.loc, |n| n.loc);
                self.err(
                    file,
                    loc,
                    path,
                    Stage::Schema,
                    format!("unknown trigger `{other}`; expected success, failure, timer or event"),
                );
                return None;
            }
            None => {
                self.err(
                    file,
                    t.loc,
                    path,
                    Stage::Schema,
                    "a transition needs `on:` (success, failure, timer or event)",
                );
                return None;
            }
        };
        let Some(to_node) = t.get("to") else {
            self.err(file, t.loc, path, Stage::Schema, "a transition needs `to:` (the target state)");
            return None;
        };
        let Some(to) = to_node.as_str() else {
            self.err(
                file,
                to_node.loc,
                path,
                Stage::Schema,
                format!("`to` must be a state name, found {}", to_node.value.kind()),
            );
            return None;
        };
        match index.get(to) {
            Some(&i) => Some((trigger, i)),
            None => {
                self.err(
                    file,
                    to_node.loc,
                    path,
                    Stage::Wiring,
                    format!("transition to undefined state `{to}`; states are: {}", names.join(", ")),
                );
                None
            }
        }
    }
}
