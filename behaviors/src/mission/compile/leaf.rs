//! Leaves and port typing: every port bound to a literal of its type or a `{reference}`.

#[allow(clippy::wildcard_imports)]
use super::*;

impl<'a> Compiler<'a> {
    pub(super) fn leaf(
        &mut self,
        spec: &NodeTypeSpec,
        key: &Key,
        body: &Node,
        file: FileId,
        path: String,
    ) -> Option<Ir> {
        let params = self.params(spec, key, body, file, &path, &["name"])?;
        let mut ok = true;
        let mut ports = Vec::new();
        for port in &spec.ports {
            let written = params.iter().find(|(k, _)| k.name == port.name);
            let (binding, loc) = match written {
                Some((_, v)) => {
                    let as_ref = v.as_str().and_then(parse_ref);
                    match (as_ref, port.ty) {
                        (Some(r), PortType::Params) => {
                            self.err(
                                file,
                                v.loc,
                                &path,
                                Stage::Schema,
                                format!(
                                    "port `{}` of `{}` takes a parameter block, not a reference `{{{r}}}`",
                                    port.name, spec.name
                                ),
                            );
                            ok = false;
                            continue;
                        }
                        (Some(r), _) => (IrBinding::Ref(r.to_string()), v.loc),
                        (None, _)
                            if port.direction == crate::registry::PortDirection::Output
                                || port.direction == crate::registry::PortDirection::InOut =>
                        {
                            self.err(
                                file,
                                v.loc,
                                &path,
                                Stage::Wiring,
                                format!(
                                    "output port `{}` of `{}` must name a blackboard entry like \"{{{}}}\", found {}",
                                    port.name,
                                    spec.name,
                                    port.name,
                                    v.value.kind()
                                ),
                            );
                            ok = false;
                            continue;
                        }
                        (None, _) => match BbValue::from_json(port.ty, &v.to_json()) {
                            Ok(val) => {
                                if let Some(msg) = range_problem(&port.name, &val) {
                                    self.err(
                                        file,
                                        v.loc,
                                        &path,
                                        Stage::Schema,
                                        format!("port `{}` of `{}`: {msg}", port.name, spec.name),
                                    );
                                    ok = false;
                                    continue;
                                }
                                (IrBinding::Literal(val), v.loc)
                            }
                            Err(e) => {
                                self.err(
                                    file,
                                    v.loc,
                                    &path,
                                    Stage::Schema,
                                    format!("port `{}` of `{}` ({}): {e}", port.name, spec.name, port.ty),
                                );
                                ok = false;
                                continue;
                            }
                        },
                    }
                }
                None => match &port.default {
                    Some(d) => match BbValue::from_json(port.ty, d) {
                        Ok(v) => (IrBinding::Literal(v), key.loc),
                        Err(_) => (IrBinding::Unset, key.loc),
                    },
                    None if port.optional => (IrBinding::Unset, key.loc),
                    None => {
                        self.err(
                            file,
                            key.loc,
                            &path,
                            Stage::Wiring,
                            format!(
                                "missing port `{}` ({}) of `{}`: {}",
                                port.name, port.ty, spec.name, port.description
                            ),
                        );
                        ok = false;
                        continue;
                    }
                },
            };
            ports.push(IrPort { spec: port.clone(), binding, loc });
        }
        ok.then(|| Ir { type_name: spec.name.to_string(), path, loc: key.loc, file, kind: IrKind::Leaf { ports } })
    }
}

/// A unit-suffix range rule: durations, distances, rates and speeds cannot be negative.
pub(super) fn range_problem(name: &str, v: &BbValue) -> Option<String> {
    let x = match v {
        BbValue::Float(f) => *f,
        BbValue::Int(i) => *i as f64,
        _ => return None,
    };
    let unit = [("_s", "seconds"), ("_m", "metres"), ("_hz", "per second"), ("_mps", "metres per second")]
        .into_iter()
        .find(|(suffix, _)| name.ends_with(suffix))
        .map(|(_, u)| u);
    match unit {
        Some(u) if x < 0.0 => Some(format!("expected a non-negative value in {u}, found {x}")),
        _ => None,
    }
}
