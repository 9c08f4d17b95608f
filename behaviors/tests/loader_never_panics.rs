//! Bad input never panics the loader: arbitrary bytes, arbitrary YAML, and arbitrary trees of
//! mission-like keys all end in diagnostics.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::io::Write;

use proptest::prelude::*;
use spomp_behaviors::engine_registry;
use spomp_behaviors::mission::load_mission;

fn load_text(text: &[u8]) -> usize {
    let dir = std::env::temp_dir().join(format!("spomp-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let name = std::thread::current().name().unwrap_or("t").replace("::", "-");
    let path = dir.join(format!("m-{name}.yaml"));
    std::fs::File::create(&path).unwrap().write_all(text).unwrap();
    load_mission(&path, &engine_registry::<()>()).diagnostics.len()
}

/// YAML-ish values whose keys are drawn from the mission language, so the loader goes deep.
fn yamlish() -> impl Strategy<Value = String> {
    let key = prop_oneof![
        Just("mission"),
        Just("team"),
        Just("roles"),
        Just("tree"),
        Just("sequence"),
        Just("children"),
        Just("child"),
        Just("timeout"),
        Just("duration_s"),
        Just("state_machine"),
        Just("states"),
        Just("initial"),
        Just("transitions"),
        Just("on"),
        Just("to"),
        Just("subtree"),
        Just("include"),
        Just("navigate_to"),
        Just("target"),
        Just("claim_goal"),
        Just("goal"),
        Just("id"),
        Just("kind"),
        Just("priority"),
        Just("start"),
        Just("time_limit_s"),
        Just("parallel"),
        Just("x"),
        Just("y")
    ];
    let leaf = prop_oneof![
        Just("1".to_string()),
        Just("-3.5".to_string()),
        Just("\"{goal}\"".to_string()),
        Just("ugv".to_string()),
        Just("~".to_string()),
        Just("[]".to_string()),
        Just("{}".to_string()),
        Just("true".to_string()),
        Just("\"{\"".to_string()),
        Just("1e999".to_string()),
        "[a-z_]{1,8}",
    ];
    leaf.prop_recursive(4, 40, 6, move |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..4).prop_map(|v| format!("[{}]", v.join(", "))),
            prop::collection::vec((key.clone(), inner), 0..5).prop_map(|kv| format!(
                "{{{}}}",
                kv.into_iter().map(|(k, v)| format!("{k}: {v}")).collect::<Vec<_>>().join(", ")
            )),
        ]
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, .. ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        prop_assert!(load_text(&bytes) > 0, "random bytes are not a valid mission");
    }

    #[test]
    fn arbitrary_yaml_never_panics(doc in yamlish()) {
        prop_assert!(load_text(doc.as_bytes()) > 0);
    }

    #[test]
    fn mutated_shipped_mission_never_panics(cut in 0usize..4000, insert in "[ :\\-\\[\\]{}a-z0-9\n]{0,6}") {
        let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../missions/visit-all-vehicle-clusters.yaml")).unwrap();
        let cut = cut.min(text.len());
        let cut = (0..=cut).rev().find(|i| text.is_char_boundary(*i)).unwrap_or(0);
        let mutated = format!("{}{}{}", &text[..cut], insert, &text[cut..]);
        let _ = load_text(mutated.as_bytes());
    }
}
