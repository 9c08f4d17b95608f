//! `subtree:` references: expansion of named subtrees, with cycle detection.

#[allow(clippy::wildcard_imports)]
use super::*;

impl<'a> Compiler<'a> {
    pub(super) fn subtree(
        &mut self,
        key: &Key,
        body: &Node,
        file: FileId,
        parent_path: &str,
        path: String,
    ) -> Option<Ir> {
        let name_node = match &body.value {
            Value::Str(_) => body,
            Value::Map(m) => {
                for (k, _) in m {
                    if k.name != "name" {
                        self.err(
                            file,
                            k.loc,
                            &path,
                            Stage::Schema,
                            format!("unknown port `{}` of node `subtree`; expected one of: name", k.name),
                        );
                        return None;
                    }
                }
                let Some(n) = body.get("name") else {
                    self.err(file, key.loc, &path, Stage::Schema, "missing port `name` of `subtree`");
                    return None;
                };
                n
            }
            other => {
                self.err(
                    file,
                    body.loc,
                    &path,
                    Stage::Schema,
                    format!("`subtree` takes a name, found {}", other.kind()),
                );
                return None;
            }
        };
        let Some(name) = name_node.as_str() else {
            self.err(
                file,
                name_node.loc,
                &path,
                Stage::Schema,
                format!("subtree name must be a string, found {}", name_node.value.kind()),
            );
            return None;
        };
        let Some(def) = self.subtrees.get(name) else {
            let known: Vec<&str> = self.subtrees.keys().map(String::as_str).collect();
            let list = if known.is_empty() {
                "none are defined".to_string()
            } else {
                format!("defined: {}", known.join(", "))
            };
            self.err(file, name_node.loc, &path, Stage::Wiring, format!("unknown subtree `{name}`; {list}"));
            return None;
        };
        if self.expanding.iter().any(|n| n == name) {
            let mut cycle = self.expanding.clone();
            cycle.push(name.to_string());
            self.err(file, name_node.loc, &path, Stage::Wiring, format!("subtree cycle: {}", cycle.join(" → ")));
            return None;
        }
        self.expanding.push(name.to_string());
        let sub_path = if parent_path.is_empty() { name.to_string() } else { format!("{parent_path}/{name}") };
        let ir = self.compile(&def.node, def.file, &sub_path);
        self.expanding.pop();
        ir
    }
}
