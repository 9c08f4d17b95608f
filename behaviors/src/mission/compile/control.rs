//! Control nodes and decorators: children, thresholds, counts and durations.

use std::time::Duration;

#[allow(clippy::wildcard_imports)]
use super::*;
use crate::control::ThresholdError;

impl<'a> Compiler<'a> {
    pub(super) fn control(
        &mut self,
        spec: &NodeTypeSpec,
        key: &Key,
        body: &Node,
        file: FileId,
        path: String,
    ) -> Option<Ir> {
        let ty = ControlType::from_name(&spec.name)?;
        // Short form: `sequence: [a, b]`.
        let (children_node, params_ok) = match &body.value {
            Value::Seq(_) => (Some(body), true),
            _ => {
                let ok = self.params(spec, key, body, file, &path, STRUCTURAL_KEYS_CONTROL).is_some();
                (body.get("children"), ok)
            }
        };
        let Some(children_node) = children_node else {
            if params_ok {
                self.err(
                    file,
                    key.loc,
                    &path,
                    Stage::Schema,
                    format!("`{}` needs `children:` (a list of nodes)", spec.name),
                );
            }
            return None;
        };
        let Some(items) = children_node.as_seq() else {
            self.err(
                file,
                children_node.loc,
                &path,
                Stage::Schema,
                format!("`children` of `{}` must be a list of nodes, found {}", spec.name, children_node.value.kind()),
            );
            return None;
        };
        if items.is_empty() {
            self.err(
                file,
                children_node.loc,
                &path,
                Stage::Schema,
                format!("`{}` needs at least one child", spec.name),
            );
            return None;
        }
        let (fewest, most) = ty.child_count();
        let mut ok = params_ok;
        if items.len() < fewest || items.len() > most {
            self.err(
                file,
                children_node.loc,
                &path,
                Stage::Schema,
                format!(
                    "`{}` takes {fewest} or {most} children (a condition, a branch run when it succeeds and an optional one run when it fails), found {}",
                    spec.name,
                    items.len()
                ),
            );
            ok = false;
        }
        let mut children = Vec::new();
        for (i, item) in items.iter().enumerate() {
            let child_path = format!("{path}[{i}]");
            match self.compile(item, file, &child_path) {
                Some(c) => children.push(c),
                None => ok = false,
            }
        }
        let n = items.len();
        let (mut success_threshold, mut failure_threshold) = (n, 1);
        if ty == ControlType::Parallel && matches!(body.value, Value::Map(_)) {
            match self.parallel_thresholds(spec, key, body, file, &path, n) {
                Some(thresholds) => (success_threshold, failure_threshold) = thresholds,
                None => ok = false,
            }
        }
        ok.then(|| Ir {
            type_name: spec.name.to_string(),
            path,
            loc: key.loc,
            file,
            kind: IrKind::Control { ty, children, success_threshold, failure_threshold },
        })
    }

    /// `parallel`'s `success_threshold` (default: every child) and `failure_threshold` (default
    /// 1), each checked against the number of children by the engine's own rule
    /// ([`ThresholdError::check`]); a value out of range is an error located at it, and the
    /// result `None`.
    fn parallel_thresholds(
        &mut self,
        spec: &NodeTypeSpec,
        key: &Key,
        body: &Node,
        file: FileId,
        path: &str,
        children: usize,
    ) -> Option<(usize, usize)> {
        let mut thresholds = [("success_threshold", children), ("failure_threshold", 1)];
        let mut ok = true;
        for (name, threshold) in &mut thresholds {
            let Some(BbValue::Int(given)) = self.literal_port(spec, body, name, file, path) else { continue };
            match ThresholdError::check(name, given, children) {
                Ok(count) => *threshold = count,
                Err(e) => {
                    let loc = body.get(name).map_or(key.loc, |v| v.loc);
                    self.err(file, loc, path, Stage::Schema, e.to_string());
                    ok = false;
                }
            }
        }
        ok.then_some((thresholds[0].1, thresholds[1].1))
    }

    pub(super) fn decorator(
        &mut self,
        spec: &NodeTypeSpec,
        key: &Key,
        body: &Node,
        file: FileId,
        path: String,
    ) -> Option<Ir> {
        let ty = DecoratorType::from_name(&spec.name)?;
        self.params(spec, key, body, file, &path, STRUCTURAL_KEYS_DECORATOR)?;
        let Some(child_node) = body.get("child") else {
            self.err(file, key.loc, &path, Stage::Schema, format!("`{}` needs `child:` (one node)", spec.name));
            return None;
        };
        let child = self.compile(child_node, file, &path);
        let mut ok = true;
        let mut duration = Duration::ZERO;
        let mut count = None;
        let mut hz = 0.0;
        let mut then_skip = false;
        let required = |c: &mut Self, name: &str| -> Option<BbValue> {
            let v = c.literal_port(spec, body, name, file, &path);
            if v.is_none() && body.get(name).is_none() {
                c.err(file, key.loc, &path, Stage::Schema, format!("missing port `{name}` of `{}`", spec.name));
            }
            v
        };
        match ty {
            DecoratorType::Timeout | DecoratorType::Delay => {
                let name = if ty == DecoratorType::Timeout { "duration_s" } else { "delay_s" };
                match required(self, name) {
                    Some(BbValue::Float(s)) => match crate::mission::limits::duration_from_secs(s) {
                        Ok(d) => duration = d,
                        Err(e) => {
                            let loc = body.get(name).map_or(key.loc, |v| v.loc);
                            self.err(file, loc, &path, Stage::Schema, format!("`{name}`: {e}"));
                            ok = false;
                        }
                    },
                    _ => ok = false,
                }
            }
            DecoratorType::Retry => match required(self, "max_attempts") {
                Some(BbValue::Int(n)) if n >= 1 => count = Some(n as u32),
                Some(BbValue::Int(n)) => {
                    let loc = body.get("max_attempts").map_or(key.loc, |v| v.loc);
                    self.err(file, loc, &path, Stage::Schema, format!("max_attempts must be at least 1, found {n}"));
                    ok = false;
                }
                _ => ok = false,
            },
            DecoratorType::Repeat => {
                if body.get("times").is_some() {
                    match self.literal_port(spec, body, "times", file, &path) {
                        Some(BbValue::Int(n)) if n >= 1 => count = Some(n as u32),
                        Some(BbValue::Int(n)) => {
                            let loc = body.get("times").map_or(key.loc, |v| v.loc);
                            self.err(
                                file,
                                loc,
                                &path,
                                Stage::Schema,
                                format!("times must be at least 1 (leave it out to repeat forever), found {n}"),
                            );
                            ok = false;
                        }
                        _ => ok = false,
                    }
                }
            }
            DecoratorType::RateLimit => match required(self, "hz") {
                Some(BbValue::Float(h)) if h > 0.0 => hz = h,
                Some(BbValue::Float(h)) => {
                    let loc = body.get("hz").map_or(key.loc, |v| v.loc);
                    self.err(file, loc, &path, Stage::Schema, format!("hz must be positive, found {h}"));
                    ok = false;
                }
                _ => ok = false,
            },
            DecoratorType::RunOnce => match self.literal_port(spec, body, "then_skip", file, &path) {
                Some(BbValue::Bool(b)) => then_skip = b,
                _ => ok &= body.get("then_skip").is_none(),
            },
            DecoratorType::Inverter
            | DecoratorType::ForceSuccess
            | DecoratorType::ForceFailure
            | DecoratorType::KeepRunningUntilFailure => {}
        }
        let child = child?;
        ok.then(|| Ir {
            type_name: spec.name.to_string(),
            path,
            loc: key.loc,
            file,
            kind: IrKind::Decorator { ty, child: Box::new(child), duration, count, hz, then_skip },
        })
    }
}
