//! The ROS 2 arguments `spomp run` takes after `--ros-args`, as `ros2 run` and launch files
//! pass them (`--ros-args -p use_sim_time:=true`, `--params-file FILE` from a launch file's
//! `parameters=[…]`).
//!
//! spomp's settings live in the mission's `ros2:` section; the one ROS parameter it reads is
//! `use_sim_time`, because launch files and `ros2 launch … use_sim_time:=true` set it for every
//! node at once. Everything else is refused with an error that says where the setting is —
//! never ignored: a remapping or parameter that silently did nothing is a robot that does not
//! do what its launch file says.

use std::collections::BTreeMap;
use std::path::Path;

/// What the ROS arguments set.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RosArgs {
    /// `use_sim_time`, if given.
    pub use_sim_time: Option<bool>,
}

/// Parses the arguments that followed `--ros-args` (up to a `--` or the end) for the node
/// `node` (its fully qualified name, `/ugv1/spomp`). `read` reads a parameters file.
pub fn parse(args: &[String], node: &str, read: &dyn Fn(&Path) -> Result<String, String>) -> Result<RosArgs, String> {
    let mut out = RosArgs::default();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value =
            |flag: &str| it.next().cloned().ok_or_else(|| format!("--ros-args {flag}: expected a value after it"));
        match a.as_str() {
            "--" => break,
            "-p" | "--param" => {
                let rule = value(a)?;
                let (name, v) =
                    rule.split_once(":=").ok_or_else(|| format!("--ros-args {a} {rule}: expected NAME:=VALUE"))?;
                let v = serde_saphyr::from_str::<serde_json::Value>(v)
                    .map_err(|e| format!("--ros-args {a} {rule}: the value is not YAML: {e}"))?;
                set(&mut out, name, &v, &format!("--ros-args {a} {rule}"))?;
            }
            "--params-file" => {
                let file = value(a)?;
                let text = read(Path::new(&file)).map_err(|e| format!("--ros-args --params-file {file}: {e}"))?;
                params_file(&mut out, &text, node, &file)?;
            }
            "-r" | "--remap" => {
                let rule = value(a)?;
                return Err(format!(
                    "--ros-args {a} {rule}: spomp run does not take remappings; its topic names, \
                     namespace and node settings are in the mission's ros2: section (ros2.topics, \
                     ros2.namespace; docs/robots.md)"
                ));
            }
            "--ros-args" => {}
            other => {
                return Err(format!(
                    "--ros-args {other}: not taken by spomp run (it takes -p/--param use_sim_time:=BOOL \
                     and --params-file FILE with use_sim_time; its other settings are in the \
                     mission's ros2: section, docs/robots.md)"
                ));
            }
        }
    }
    Ok(out)
}

/// Applies one parameter.
fn set(out: &mut RosArgs, name: &str, value: &serde_json::Value, place: &str) -> Result<(), String> {
    match (name, value) {
        ("use_sim_time", serde_json::Value::Bool(b)) => {
            out.use_sim_time = Some(*b);
            Ok(())
        }
        ("use_sim_time", v) => Err(format!("{place}: use_sim_time must be true or false, found {v}")),
        (other, _) => Err(format!(
            "{place}: `{other}` is not a parameter spomp run reads; use_sim_time is the one ROS \
             parameter it takes, its other settings are in the mission's ros2: section (docs/robots.md)"
        )),
    }
}

/// Applies the `ros__parameters` of every entry of a parameters file that names `node`:
/// `/**` (every node), the node's fully qualified name, its base name, `/**/name`.
fn params_file(out: &mut RosArgs, text: &str, node: &str, file: &str) -> Result<(), String> {
    let entries: BTreeMap<String, serde_json::Value> =
        serde_saphyr::from_str(text).map_err(|e| format!("--ros-args --params-file {file}: {e}"))?;
    let base = node.rsplit('/').next().unwrap_or(node);
    for (pattern, entry) in &entries {
        let p = pattern.trim_start_matches('/');
        let applies = p == "**"
            || p == node.trim_start_matches('/')
            || p == base
            || p.strip_prefix("**/").is_some_and(|n| n == base);
        if !applies {
            continue;
        }
        let params = entry
            .get("ros__parameters")
            .and_then(|p| p.as_object())
            .ok_or_else(|| format!("--ros-args --params-file {file}: `{pattern}` has no ros__parameters map"))?;
        for (name, v) in params {
            set(out, name, v, &format!("--ros-args --params-file {file}: {pattern}.ros__parameters.{name}"))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(a: &[&str]) -> Vec<String> {
        a.iter().map(|s| s.to_string()).collect()
    }

    fn no_file(_: &Path) -> Result<String, String> {
        Err("no file".into())
    }

    #[test]
    fn use_sim_time_as_a_parameter_in_every_spelling() {
        for (a, want) in [
            (args(&["-p", "use_sim_time:=true"]), Some(true)),
            (args(&["--param", "use_sim_time:=True"]), Some(true)),
            (args(&["-p", "use_sim_time:=false"]), Some(false)),
            (args(&["-p", "use_sim_time:=true", "--", "ignored"]), Some(true)),
            (args(&[]), None),
        ] {
            assert_eq!(parse(&a, "/ugv1/spomp", &no_file).unwrap().use_sim_time, want, "{a:?}");
        }
    }

    #[test]
    fn a_launch_files_parameters_file_applies_to_matching_nodes_only() {
        let file = |_: &Path| {
            Ok("/**:\n  ros__parameters:\n    use_sim_time: true\n/other/node:\n  ros__parameters:\n    foo: 1\n"
                .to_string())
        };
        let a = args(&["--params-file", "/tmp/launch_params_x"]);
        assert_eq!(parse(&a, "/ugv1/spomp", &file).unwrap().use_sim_time, Some(true));
        let named = |_: &Path| Ok("ugv1/spomp:\n  ros__parameters:\n    use_sim_time: false\n".to_string());
        assert_eq!(parse(&a, "/ugv1/spomp", &named).unwrap().use_sim_time, Some(false));
    }

    #[test]
    fn everything_else_is_refused_naming_the_argument() {
        let e = parse(&args(&["-p", "max_speed:=2.0"]), "/ugv1/spomp", &no_file).unwrap_err();
        assert!(e.contains("`max_speed` is not a parameter spomp run reads"), "{e}");
        let e = parse(&args(&["-p", "use_sim_time:=yes please"]), "/ugv1/spomp", &no_file).unwrap_err();
        assert!(e.contains("use_sim_time must be true or false"), "{e}");
        let e = parse(&args(&["-r", "__ns:=/husky"]), "/ugv1/spomp", &no_file).unwrap_err();
        assert!(e.contains("ros2.namespace"), "{e}");
        let e = parse(&args(&["--log-level", "debug"]), "/ugv1/spomp", &no_file).unwrap_err();
        assert!(e.contains("--ros-args --log-level: not taken"), "{e}");
        let e = parse(&args(&["-p"]), "/ugv1/spomp", &no_file).unwrap_err();
        assert!(e.contains("expected a value"), "{e}");
        let e = parse(&args(&["--params-file", "missing.yaml"]), "/ugv1/spomp", &no_file).unwrap_err();
        assert!(e.contains("missing.yaml: no file"), "{e}");
        let bad = |_: &Path| Ok("/**:\n  ros__parameters:\n    use_sim_time: true\n    rate: 5\n".to_string());
        let e = parse(&args(&["--params-file", "p.yaml"]), "/ugv1/spomp", &bad).unwrap_err();
        assert!(e.contains("/**.ros__parameters.rate: `rate` is not a parameter"), "{e}");
    }
}
