//! The JSON Schema of the mission language: the typed sections come from the serde types
//! (schemars), the behaviour-tree nodes from the node manifest, so both stay in step with the
//! code. Editors use it through the YAML language server (see the mission authoring guide).

use serde_json::{Map, Value, json};

use crate::blackboard::PortType;
use crate::registry::{Category, NodeCatalog, NodeTypeSpec, PortDirection};

use super::schema::MissionFile;
use super::sections::{SECTION_SLOTS, SectionOwner, SectionPlace};

const REF_PATTERN: &str = r"^\{[A-Za-z_][A-Za-z0-9_.]*\}$";

fn port_value_schema(ty: PortType) -> Value {
    let point = json!({"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}}, "required": ["x", "y"], "additionalProperties": false});
    match ty {
        PortType::Bool => json!({"type": "boolean"}),
        PortType::Int => json!({"type": "integer"}),
        PortType::Float => json!({"type": "number"}),
        PortType::String | PortType::Robot => json!({"type": "string"}),
        PortType::Point => point,
        PortType::Pose => {
            json!({"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "yaw": {"type": "number"}}, "required": ["x", "y"], "additionalProperties": false})
        }
        PortType::Goal => json!({"type": "string", "pattern": REF_PATTERN}),
        PortType::Points => json!({"type": "array", "items": point}),
        PortType::Params => json!({"type": "object"}),
        PortType::Any => json!({}),
    }
}

fn node_body_schema(spec: &NodeTypeSpec) -> Value {
    let tree = json!({"$ref": "#/$defs/TreeNode"});
    let mut props = Map::new();
    let mut required = Vec::new();
    props
        .insert("name".into(), json!({"type": "string", "description": "Display name used in node paths and traces."}));
    for p in &spec.ports {
        let reference =
            json!({"type": "string", "pattern": REF_PATTERN, "description": "A blackboard entry, like \"{goal}\"."});
        let schema = match (p.direction, p.ty) {
            (PortDirection::Output | PortDirection::InOut, _) => reference,
            (_, PortType::Params) => port_value_schema(p.ty),
            _ if matches!(
                spec.category,
                Category::Control | Category::Decorator | Category::StateMachine | Category::Subtree
            ) =>
            {
                port_value_schema(p.ty)
            }
            _ => json!({"anyOf": [port_value_schema(p.ty), reference]}),
        };
        let mut schema = schema;
        if let Value::Object(o) = &mut schema {
            let mut desc = format!(
                "{} ({}{})",
                p.description,
                p.ty,
                if p.direction == PortDirection::Input { "" } else { ", output" }
            );
            if let Some(d) = &p.default {
                desc.push_str(&format!(" Default: {d}."));
            }
            o.insert("description".into(), Value::String(desc));
        }
        props.insert(p.name.to_string(), schema);
        if !p.optional && p.default.is_none() {
            required.push(Value::String(p.name.to_string()));
        }
    }
    match spec.category {
        Category::Control => {
            let mut list = json!({"type": "array", "items": tree, "minItems": 1});
            if let Some((fewest, most)) = crate::control::ControlType::from_name(&spec.name).map(|t| t.child_count())
                && let Value::Object(o) = &mut list
            {
                o.insert("minItems".into(), json!(fewest));
                if most != usize::MAX {
                    o.insert("maxItems".into(), json!(most));
                }
            }
            props.insert("children".into(), list.clone());
            json!({"anyOf": [
                list,
                {"type": "object", "properties": props, "required": ["children"], "additionalProperties": false}
            ]})
        }
        Category::Decorator => {
            props.insert("child".into(), tree);
            required.push(Value::String("child".into()));
            json!({"type": "object", "properties": props, "required": required, "additionalProperties": false})
        }
        Category::StateMachine => {
            props.insert(
                "states".into(),
                json!({"type": "object", "additionalProperties": {"$ref": "#/$defs/State"}, "minProperties": 1}),
            );
            json!({"type": "object", "properties": props, "required": ["initial", "states"], "additionalProperties": false})
        }
        Category::Subtree => {
            json!({"anyOf": [{"type": "string"}, {"type": "object", "properties": props, "required": ["name"], "additionalProperties": false}]})
        }
        Category::Action | Category::Condition => {
            let obj =
                json!({"type": "object", "properties": props, "required": required, "additionalProperties": false});
            if required.is_empty() { json!({"anyOf": [{"type": "null"}, obj]}) } else { obj }
        }
    }
}

/// The JSON Schema of mission files for a registry.
pub fn mission_schema(registry: &NodeCatalog) -> Value {
    let schema = schemars::schema_for!(MissionFile);
    let mut root = serde_json::to_value(&schema).unwrap_or_else(|_| json!({}));
    let variants: Vec<Value> = registry
        .iter()
        .map(|spec| {
            let mut props = Map::new();
            let mut body = node_body_schema(spec);
            if let Value::Object(o) = &mut body {
                o.insert("description".into(), Value::String(spec.description.to_string()));
            }
            props.insert(spec.name.to_string(), body);
            json!({"type": "object", "properties": props, "required": [spec.name], "additionalProperties": false})
        })
        .collect();
    let tree =
        json!({"description": "A behaviour-tree node: one key, the node type, holding its ports.", "oneOf": variants});
    let state = json!({
        "type": "object",
        "properties": {
            "run": {"$ref": "#/$defs/TreeNode"},
            "description": {"type": "string"},
            "terminal": {"enum": ["success", "failure"]},
            "transitions": {"type": "array", "items": {
                "type": "object",
                "properties": {
                    "on": {"enum": ["success", "failure", "timer", "event"]},
                    "to": {"type": "string"},
                    "after_s": {"type": "number", "minimum": 0},
                    "event": {"type": "string"}
                },
                "required": ["on", "to"],
                "additionalProperties": false
            }}
        },
        "additionalProperties": false
    });
    if let Some(Value::Object(defs)) = root.get_mut("$defs") {
        defs.insert("TreeNode".into(), tree);
        defs.insert("State".into(), state);
    }
    if let Some(checks) = registry.robot_checks() {
        let mut nav = checks.navigation_schema();
        let nav_defs = nav.as_object_mut().and_then(|o| o.remove("$defs"));
        if let Some(o) = nav.as_object_mut() {
            o.remove("$schema");
        }
        if let Some(Value::Object(defs)) = root.get_mut("$defs") {
            if let Some(Value::Object(extra)) = nav_defs {
                for (k, v) in extra {
                    defs.entry(k).or_insert(v);
                }
            }
            defs.insert("Navigation".into(), nav);
            for owner in ["RoleSpec", "RobotSpec"] {
                if let Some(p) = defs.get_mut(owner).and_then(|d| d.pointer_mut("/properties/navigation")) {
                    let description = p.get("description").cloned().unwrap_or(Value::Null);
                    *p = json!({"description": description, "$ref": "#/$defs/Navigation"});
                }
            }
        }
    }
    for owner in registry.section_owners() {
        insert_section(&mut root, owner);
    }
    if let Value::Object(o) = &mut root {
        o.insert("title".into(), Value::String("spomp mission".into()));
    }
    root
}

/// An adapter section's schema, from its owner: its definitions added to the mission's, its
/// slot (top level or in each robot) pointing at it with the slot's own description.
fn insert_section(root: &mut Value, owner: &dyn SectionOwner) {
    let Some(place) = SECTION_SLOTS.iter().find(|(n, _)| *n == owner.name()).map(|(_, p)| *p) else { return };
    let mut schema = owner.schema();
    let extra = schema.as_object_mut().and_then(|o| o.remove("$defs"));
    if let Some(o) = schema.as_object_mut() {
        o.remove("$schema");
        o.remove("title");
    }
    let name = owner.def_name();
    let reference = json!({"$ref": format!("#/$defs/{name}")});
    let slot = match owner.default_value() {
        Some(default) => json!({"$ref": format!("#/$defs/{name}"), "default": default}),
        None => json!({"anyOf": [reference, {"type": "null"}], "default": null}),
    };
    let pointer = match place {
        SectionPlace::Mission => format!("/properties/{}", owner.name()),
        SectionPlace::Robot => format!("/$defs/RobotSpec/properties/{}", owner.name()),
    };
    if let Some(p) = root.pointer_mut(&pointer) {
        let description = p.get("description").cloned().unwrap_or(Value::Null);
        let mut slot = slot;
        if let Value::Object(o) = &mut slot {
            o.insert("description".into(), description);
        }
        *p = slot;
    }
    if let Some(Value::Object(defs)) = root.get_mut("$defs") {
        if let Some(Value::Object(extra)) = extra {
            for (k, v) in extra {
                defs.entry(k).or_insert(v);
            }
        }
        defs.insert(name, schema);
    }
}
