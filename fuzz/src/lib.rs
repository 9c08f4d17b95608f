//! The bodies of spomp's fuzz targets, one public function per target.
//!
//! Each function takes the fuzzer's bytes and drives the same public function the `spomp`
//! command line uses for that input (the mission loader, `World::load`, the mission builder that
//! reads QGroundControl plans, the team-state decoder, the team link's receive path, the MCAP log
//! reader, checker and recoverer, the depth-panorama reader and terrain analysis). A panic, an abort, a hang or a memory blow-up
//! is a finding; a clean error is not. Some targets also check a property (a recovered log checks
//! as closed, a decoded sync message re-encodes to something that decodes the same).
//!
//! The binaries in `fuzz_targets/` are one-line `fuzz_target!` wrappers around these functions,
//! and the unit tests at the bottom replay every kept input (`corpus/` and `regressions/`)
//! through them with a plain `cargo test`.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use arbitrary::Unstructured;
use spomp_behaviors::blackboard::Blackboard;
use spomp_behaviors::mission::{BuildOptions, LoadOptions, LoadedMission, Rendered, build_tree, load_mission_with};
use spomp_behaviors::registry::{Category, NodeRegistry};
use spomp_robot::RobotRuntime;

thread_local! {
    /// The command line's node registry, built once per fuzzing process, with the owners of the
    /// mission sections this crate links (`sim:`, `team_link:`; `comms:` comes with the robot's;
    /// the fuzz crate does not link the ROS 2 adapter, so a `ros2:` section is kept unchecked).
    static REGISTRY: NodeRegistry<RobotRuntime> = {
        let mut r = spomp_robot::registry();
        r.register_section(spomp_behaviors::mission::owner::<spomp_world::SimSpec>());
        r.register_section(spomp_behaviors::mission::owner::<spomp_zenoh::TeamLinkSpec>());
        r
    };
}

/// A scratch folder for this process and target (in memory when `/dev/shm` exists): the loaders
/// under test read files, so the input is written there first.
fn scratch(target: &str) -> PathBuf {
    let base = if Path::new("/dev/shm").is_dir() { PathBuf::from("/dev/shm") } else { std::env::temp_dir() };
    let dir = base.join(format!("spomp-fuzz-{}-{target}", std::process::id()));
    if !dir.is_dir() {
        std::fs::create_dir_all(&dir).expect("the fuzzer needs a scratch folder");
    }
    dir
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes).expect("the fuzzer needs to write its input");
}

/// What `spomp validate` does with a loaded mission's problems: each rendered with the offending
/// line of its file, and the whole list as JSON.
fn render(loaded: &LoadedMission) {
    let handler = miette::GraphicalReportHandler::new_themed(miette::GraphicalTheme::unicode_nocolor());
    let mut human = String::new();
    for d in &loaded.diagnostics {
        let _ = writeln!(human, "{d}");
        let src = loaded.source_of(&d.file).unwrap_or_default().to_string();
        let _ = handler.render_report(&mut human, &Rendered::new(d.clone(), src));
    }
    let _ = serde_json::to_string_pretty(&loaded.diagnostics);
}

fn load_and_render(path: &Path) -> LoadedMission {
    let loaded = REGISTRY.with(|r| load_mission_with(path, r, &LoadOptions::default()));
    render(&loaded);
    loaded
}

/// The mission loader on raw bytes: the bytes are the mission file.
pub fn mission_bytes(data: &[u8]) {
    let path = scratch("mission_bytes").join("mission.yaml");
    write(&path, data);
    load_and_render(&path);
}

/// The mission loader on structure-aware YAML: the bytes choose a mission — a team, roles whose
/// trees are made of the registry's node types with port values of every kind (numbers at and
/// past their limits, NaN, infinities, blackboard references, lists, maps), a completion rule,
/// a time limit and stray keys — which is written as YAML and loaded.
pub fn mission_yaml(data: &[u8]) {
    let mut u = Unstructured::new(data);
    let text = REGISTRY.with(|r| MissionGen { registry: r }.mission(&mut u).unwrap_or_default());
    let path = scratch("mission_yaml").join("mission.yaml");
    write(&path, text.as_bytes());
    load_and_render(&path);
}

/// Writes YAML for a mission from fuzzer bytes.
struct MissionGen<'a> {
    registry: &'a NodeRegistry<RobotRuntime>,
}

const KINDS: &[&str] = &["ugv", "uav", "basestation", "boat", ""];
const IDS: &[&str] = &["base", "uav1", "ugv1", "ugv2", "ugv3", "../x", "a b", ""];
const ROLES: &[&str] = &["r0", "r1", "r2", "missing"];
const ENTRIES: &[&str] = &["{target}", "{goal}", "{robot_id}", "{home}", "{start_pose}", "{x}", "{", "{}"];
const COMPLETE: &[&str] = &["all_goals_visited", "time_limit", "all_robots_done", "never"];
const STRINGS: &[&str] = &["", "explore.plan", "/etc/passwd", "../../x", "ugv1", "é", "\u{0}", "a\nb"];

impl MissionGen<'_> {
    fn mission(&self, u: &mut Unstructured<'_>) -> arbitrary::Result<String> {
        let mut y = String::new();
        let _ = writeln!(y, "mission: {}", quote(u.choose(IDS)?));
        y.push_str("team:\n");
        for _ in 0..u.int_in_range(0..=4)? {
            let _ = write!(
                y,
                "  - {{ id: {}, kind: {}, role: {}, start: {{ x_m: {}, y_m: {} }}",
                quote(u.choose(IDS)?),
                quote(u.choose(KINDS)?),
                quote(u.choose(ROLES)?),
                number(u)?,
                number(u)?
            );
            if u.arbitrary()? {
                let _ = write!(y, ", priority: {}", u.arbitrary::<i64>()?);
            }
            y.push_str(" }\n");
        }
        y.push_str("roles:\n");
        for role in ROLES.iter().take(u.int_in_range(0..=3)?) {
            let _ = writeln!(y, "  {role}:\n    tree: {}", self.tree(u, 0)?);
            if u.arbitrary()? {
                let _ = writeln!(y, "    blackboard: {{ x: {}, goal: {} }}", self.value(u, 1)?, self.value(u, 1)?);
            }
            if u.arbitrary()? {
                let _ = writeln!(y, "    tick_hz: {}", number(u)?);
            }
        }
        let _ = writeln!(y, "complete_when: {}", u.choose(COMPLETE)?);
        let _ = writeln!(y, "time_limit_s: {}", number(u)?);
        if u.arbitrary()? {
            let _ = writeln!(y, "sim: {{ world: {{ generate: {{ size_m: [{}, {}] }} }} }}", number(u)?, number(u)?);
        }
        if u.arbitrary()? {
            let _ =
                writeln!(y, "{}: {}", u.choose(&["include", "subtrees", "navigation", "bogus"])?, self.value(u, 0)?);
        }
        Ok(y)
    }

    fn tree(&self, u: &mut Unstructured<'_>, depth: usize) -> arbitrary::Result<String> {
        let specs: Vec<_> = self.registry.iter().collect();
        let spec = u.choose(&specs)?;
        let deeper = depth < 6;
        let body = match spec.category {
            Category::Control => {
                let n = if deeper { u.int_in_range(0..=3)? } else { 0 };
                let kids = (0..n).map(|_| self.tree(u, depth + 1)).collect::<arbitrary::Result<Vec<_>>>()?;
                format!("[{}]", kids.join(", "))
            }
            Category::Decorator => {
                let child = if deeper { self.tree(u, depth + 1)? } else { "{ always_success: {} }".into() };
                format!("{{ child: {child}{} }}", self.ports(u, spec.ports.iter().map(|p| &*p.name), true)?)
            }
            Category::StateMachine => {
                let run = if deeper { self.tree(u, depth + 1)? } else { "{}".into() };
                format!(
                    "{{ initial: a, states: {{ a: {{ run: {run}, transitions: [{{ on: {}, after_s: {}, to: {} }}] }}, b: {{}} }} }}",
                    u.choose(&["success", "failure", "timer", "bogus"])?,
                    number(u)?,
                    u.choose(&["a", "b", "c"])?
                )
            }
            Category::Subtree => quote(u.choose(&["s", "missing", ""])?),
            Category::Action | Category::Condition => {
                format!("{{ {} }}", self.ports(u, spec.ports.iter().map(|p| &*p.name), false)?.trim_start_matches(", "))
            }
        };
        Ok(format!("{{ {}: {body} }}", spec.name))
    }

    /// `, port: value` for some of the node's ports (and now and then one it does not have).
    fn ports<'n>(
        &self,
        u: &mut Unstructured<'_>,
        names: impl Iterator<Item = &'n str>,
        leading_comma: bool,
    ) -> arbitrary::Result<String> {
        let mut out = String::new();
        let mut names: Vec<&str> = names.collect();
        names.push("bogus_port");
        for name in names {
            if u.ratio(1, 2)? {
                let _ = write!(out, ", {name}: {}", self.value(u, 0)?);
            }
        }
        if !leading_comma {
            return Ok(out.trim_start_matches(", ").to_string());
        }
        Ok(out)
    }

    fn value(&self, u: &mut Unstructured<'_>, depth: usize) -> arbitrary::Result<String> {
        Ok(match u.int_in_range(0..=7)? {
            0 => number(u)?,
            1 => u.arbitrary::<i64>()?.to_string(),
            2 => u.arbitrary::<bool>()?.to_string(),
            3 => quote(u.choose(STRINGS)?),
            4 => quote(u.choose(ENTRIES)?),
            5 if depth < 3 => {
                let n = u.int_in_range(0..=3)?;
                let items = (0..n).map(|_| self.value(u, depth + 1)).collect::<arbitrary::Result<Vec<_>>>()?;
                format!("[{}]", items.join(", "))
            }
            6 if depth < 3 => format!("{{ x: {}, y: {} }}", number(u)?, number(u)?),
            _ => "~".into(),
        })
    }
}

/// A YAML number: ordinary, at a limit, or hostile (`.nan`, `.inf`, 1e308, tiny, huge integers).
fn number(u: &mut Unstructured<'_>) -> arbitrary::Result<String> {
    Ok(match u.int_in_range(0..=4)? {
        0 => u.int_in_range(-5i32..=1000)?.to_string(),
        1 => {
            let f: f64 = u.arbitrary()?;
            if f.is_nan() {
                ".nan".into()
            } else if f.is_infinite() {
                if f > 0.0 { ".inf".into() } else { "-.inf".into() }
            } else {
                format!("{f:e}")
            }
        }
        2 => u
            .choose(&[".nan", ".inf", "-.inf", "1e308", "-1e308", "1e-300", "0", "-0.0", "18446744073709551616"])?
            .to_string(),
        3 => format!("{}.5", u.int_in_range(0u32..=100_000)?),
        _ => u.arbitrary::<u64>()?.to_string(),
    })
}

/// A double-quoted YAML string.
fn quote(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// World metadata and layers: the bytes choose a `world.yaml` (numbers of every kind, layer
/// file names, an inline or missing class table, metadata points) and the class, elevation and
/// colour PNGs (well-formed images of the bytes' size and pixels, with colours from the class
/// table or not, or raw bytes), and `World::load` reads the folder as `spomp world show` does.
pub fn world(data: &[u8]) {
    let dir = scratch("world");
    let mut u = Unstructured::new(data);
    let Ok(()) = world_files(&mut u, &dir) else { return };
    if let Ok(w) = spomp_world::World::load(&dir) {
        // What `world show` does next.
        let _ = spomp_world::render_png(&w);
    }
}

/// Class colours of the default table, for class layers that mostly load.
const CLASS_COLORS: &[[u8; 3]] =
    &[[128, 64, 128], [70, 70, 70], [107, 142, 35], [0, 0, 142], [244, 35, 232], [0, 0, 0], [255, 255, 255]];

fn world_files(u: &mut Unstructured<'_>, dir: &Path) -> arbitrary::Result<()> {
    let mut y = String::new();
    if u.ratio(1, 8)? {
        // Now and then the description is raw bytes.
        let raw: &[u8] = u.arbitrary()?;
        write(&dir.join("world.yaml"), raw);
    } else {
        let _ = writeln!(y, "resolution_m: {}", number(u)?);
        if u.arbitrary()? {
            let _ = writeln!(y, "origin: {{ x: {}, y: {} }}", number(u)?, number(u)?);
        }
        if u.arbitrary()? {
            let _ = writeln!(y, "width: {}", number(u)?);
        }
        if u.arbitrary()? {
            let _ = writeln!(y, "height: {}", number(u)?);
        }
        match u.int_in_range(0..=3)? {
            0 => {}
            1 => y.push_str("class_table: classes.yaml\n"),
            2 => y.push_str(
                "class_table:\n  classes:\n    - { index: 0, name: road, color: [128, 64, 128], traversable: true }\n",
            ),
            _ => y.push_str("class_table: ../../etc/passwd\n"),
        }
        y.push_str("layers:\n  class: class.png\n");
        if u.arbitrary()? {
            let _ = writeln!(
                y,
                "  elevation: {{ file: elevation.png, scale_m: {}, offset_m: {} }}",
                number(u)?,
                number(u)?
            );
        }
        if u.arbitrary()? {
            y.push_str("  color: color.png\n");
        }
        y.push_str("meta:\n");
        for key in ["vehicle_clusters", "roadblocks", "start_poses"] {
            let n = u.int_in_range(0..=2)?;
            let pts = (0..n)
                .map(|_| {
                    let (a, b, c) = (number(u)?, number(u)?, number(u)?);
                    Ok(if key == "start_poses" {
                        format!("{{ x: {a}, y: {b}, yaw: {c} }}")
                    } else {
                        format!("{{ x: {a}, y: {b} }}")
                    })
                })
                .collect::<arbitrary::Result<Vec<_>>>()?;
            let _ = writeln!(y, "  {key}: [{}]", pts.join(", "));
        }
        if u.ratio(1, 16)? {
            y.push_str(u.choose(&["bogus: 1\n", "layers: 3\n", "meta: [\n", "resolution_m: 2\n"])?);
        }
        write(&dir.join("world.yaml"), y.as_bytes());
    }
    let (w, h) = (u.int_in_range(0u32..=24)?, u.int_in_range(0u32..=24)?);
    write(&dir.join("class.png"), &layer_png(u, w, h, Layer::Class)?);
    write(&dir.join("elevation.png"), &layer_png(u, w, h, Layer::Elevation)?);
    write(&dir.join("color.png"), &layer_png(u, w, h, Layer::Color)?);
    Ok(())
}

#[derive(Clone, Copy, PartialEq)]
enum Layer {
    Class,
    Elevation,
    Color,
}

/// A layer file: mostly a PNG of the grid's size (sometimes another size or pixel type), now
/// and then raw bytes.
fn layer_png(u: &mut Unstructured<'_>, w: u32, h: u32, layer: Layer) -> arbitrary::Result<Vec<u8>> {
    let choice = u.int_in_range(0..=9)?;
    if choice == 0 {
        return Ok(u.arbitrary::<&[u8]>()?.to_vec());
    }
    let (w, h) = if choice == 1 { (u.int_in_range(0u32..=24)?, u.int_in_range(0u32..=24)?) } else { (w, h) };
    let mut bytes = Vec::new();
    let mut cursor = std::io::Cursor::new(&mut bytes);
    let n = (w * h) as usize;
    let encoded = if (layer == Layer::Elevation) != (choice == 2) {
        let mut px = Vec::with_capacity(n);
        for _ in 0..n {
            px.push(u.arbitrary::<u16>().unwrap_or(0));
        }
        image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, px)
            .map(|img| img.write_to(&mut cursor, image::ImageFormat::Png))
    } else {
        let mut px = Vec::with_capacity(n * 3);
        for _ in 0..n {
            let c = if layer == Layer::Class && u.ratio(15, 16).unwrap_or(true) {
                *u.choose(CLASS_COLORS).unwrap_or(&[0, 0, 0])
            } else {
                u.arbitrary::<[u8; 3]>().unwrap_or_default()
            };
            px.extend_from_slice(&c);
        }
        image::RgbImage::from_raw(w, h, px).map(|img| img.write_to(&mut cursor, image::ImageFormat::Png))
    };
    match encoded {
        Some(Ok(())) => Ok(bytes),
        // A zero-sized image does not encode: an empty file stands for it.
        _ => Ok(Vec::new()),
    }
}

/// A mission whose UAV flies a QGroundControl plan: the plan is read when the mission's tree is
/// built, as `spomp sim` and `validate --dry-run` build it.
const PLAN_MISSION: &str = "mission: plan\nteam:\n  - { id: uav1, kind: uav, role: explorer, start: { x_m: 10, y_m: 10 } }\n\
roles:\n  explorer:\n    tree:\n      follow_waypoints: { plan_file: fuzz.plan, altitude_m: 60, speed_mps: 10, progress: \"{next}\" }\n\
    blackboard: { next: 0 }\ncomplete_when: time_limit\ntime_limit_s: 600\n";

/// QGroundControl plans: the bytes are the `.plan` file of a UAV's `follow_waypoints`, and the
/// mission's tree is built (which reads and checks the plan).
pub fn qgc_plan(data: &[u8]) {
    let dir = scratch("qgc_plan");
    let mission = dir.join("mission.yaml");
    if !mission.is_file() {
        write(&mission, PLAN_MISSION.as_bytes());
    }
    write(&dir.join("fuzz.plan"), data);
    REGISTRY.with(|r| {
        let loaded = load_mission_with(&mission, r, &LoadOptions::default());
        // The mission itself is valid; should loading ever read the plan, a bad plan stops here.
        let Some(role) = loaded.roles.get("explorer") else { return };
        let options = BuildOptions { base_dir: Some(loaded.base_dir()), ..BuildOptions::default() };
        let _ = build_tree(&role.tree, r, &mut Blackboard::new(), options);
    });
}

/// Team-state sync messages as they arrive over the radio: applied by a robot (`ugv2`) as from
/// `ugv1`, which decodes them with its size limit, checks every record and merges them, then
/// answers. A message that decodes must re-encode to bytes that decode to the same encoding.
pub fn teamstate_sync(data: &[u8]) {
    use spomp_core::RobotId;
    use spomp_teamstate::{SyncMessage, TeamState, TeamStateParams, TierSet};
    if let Ok(msg) = SyncMessage::decode_with_limit(data, TeamStateParams::default().max_message_bytes) {
        let again = msg.encode();
        let back = SyncMessage::decode(&again).expect("a re-encoded message decodes");
        assert_eq!(back.encode(), again, "encoding is stable");
    }
    let (me, peer) = (RobotId::new("ugv2"), RobotId::new("ugv1"));
    let Ok(mut state) = TeamState::new(me, 2, TeamStateParams::default()) else { return };
    if state.apply_bytes(&peer, data).is_ok() {
        let _ = state.goals();
        let _ = state.make_sync(&peer, TierSet::ALL, usize::MAX);
    }
}

/// The team link's members in [`teamlink_receive`]: name and key seed.
const LINK_MEMBERS: [(&str, u8); 3] = [("base", 1), ("ugv1", 2), ("uav1", 3)];
/// The message size limit in [`teamlink_receive`] (small, so oversized messages are cheap).
const LINK_MAX_MESSAGE_BYTES: usize = 1 << 16;

/// A secured team state of a [`LINK_MEMBERS`] member, session `session`.
fn link_member(name: &str, session: u64) -> spomp_teamstate::TeamState {
    use spomp_core::RobotId;
    use spomp_teamstate::{TeamKeys, TeamSecurity, TeamState, TeamStateParams};
    let mut keys = TeamKeys::new("fuzz-team");
    for (member, seed) in LINK_MEMBERS {
        keys.add(RobotId::new(member), &TeamSecurity::public_key_of(&[seed; 32])).expect("a valid key");
    }
    let seed = LINK_MEMBERS.iter().find(|m| m.0 == name).map_or(0, |m| m.1);
    let params = TeamStateParams { max_message_bytes: LINK_MAX_MESSAGE_BYTES, ..TeamStateParams::default() };
    let mut state = TeamState::new(RobotId::new(name), 5, params).expect("valid parameters");
    let security = TeamSecurity::new(RobotId::new(name), &[seed; 32], std::sync::Arc::new(keys)).expect("a member");
    state.set_security(std::sync::Arc::new(security)).expect("its own key");
    state.set_session(session);
    state
}

/// Team-link messages as a robot receives them from the transport, through the whole receive
/// path: the link's intake (`spomp_zenoh::Intake`: the sender named by the key expression,
/// the member list, the size limit, the bounded inbox), then the secured team state's
/// `apply_bytes` (decoding, addresses, records, every signature, session and replay checks).
/// The bytes choose a sequence of deliveries to the basestation: genuine signed messages of
/// ugv1 (made on the spot), any bytes under any key expression, replays and bit flips of
/// genuine messages, oversized payloads, and inbox drains. Properties: a refused payload is
/// never copied, the link's per-sender figures name members only, every offered message is
/// either kept or counted, only members' messages reach the team state, and a message it
/// refuses leaves its every table as it was.
pub fn teamlink_receive(data: &[u8]) {
    use spomp_core::{Pose2, RobotId, Time};
    use spomp_teamstate::TierSet;
    use spomp_zenoh::{Intake, LinkConfig};

    let mut u = Unstructured::new(data);
    let mut config = LinkConfig::new("fuzz-team", RobotId::new("base"));
    config.members = Some(LINK_MEMBERS.iter().map(|m| RobotId::new(m.0)).collect());
    config.max_message_bytes = LINK_MAX_MESSAGE_BYTES;
    config.queue_messages = 8;
    let intake = Intake::new(&config);
    let mut base = link_member("base", 10);
    let mut ugv1 = link_member("ugv1", 20);
    let key = |from: &str| format!("spomp/fuzz-team/team/base/{from}/coordination");
    let mut genuine: Vec<Vec<u8>> = Vec::new();
    let mut offered = 0u64;
    let drain = |intake: &Intake, base: &mut spomp_teamstate::TeamState| {
        for (from, bytes) in intake.take() {
            assert!(LINK_MEMBERS.iter().any(|m| m.0 == from.as_str()), "kept a message of non-member {from}");
            let (sizes, records) = (base.table_sizes(), base.records().count());
            if base.apply_bytes(&from, &bytes).is_err() {
                assert_eq!(base.table_sizes(), sizes, "a refused message changed a table");
                assert_eq!(base.records().count(), records);
            }
        }
    };
    for step in 0..48u32 {
        // Out of bytes, `Unstructured` would answer zeros: stop instead.
        if u.is_empty() {
            break;
        }
        let Ok(op) = u.int_in_range(0u8..=6) else { break };
        match op {
            // A genuine message of ugv1, delivered.
            0 => {
                let _ = ugv1.set_pose(Pose2::new(f64::from(step), 1.0, 0.0), Time::from_secs_f64(f64::from(step)));
                if let Some(m) = ugv1.make_sync(&RobotId::new("base"), TierSet::ALL, 4096) {
                    let bytes = m.encode();
                    offered += 1;
                    intake.offer(&key("ugv1"), bytes.len(), || bytes.clone());
                    genuine.push(bytes);
                }
            }
            // Any bytes under a member's name or any name (any key expression chunk).
            1 | 2 => {
                let from = if op == 1 {
                    u.choose(&LINK_MEMBERS).map_or("ugv1", |m| m.0).to_string()
                } else {
                    u.arbitrary::<String>().unwrap_or_default()
                };
                let bytes: Vec<u8> = u.arbitrary().unwrap_or_default();
                offered += 1;
                intake.offer(&key(&from), bytes.len(), || bytes.clone());
            }
            // A genuine message again, or with bytes changed.
            3 | 4 if !genuine.is_empty() => {
                let pick = u.choose_index(genuine.len()).unwrap_or(0);
                let mut bytes = genuine[pick].clone();
                if op == 4 {
                    for _ in 0..u.int_in_range(1u8..=4).unwrap_or(1) {
                        let at = u.choose_index(bytes.len()).unwrap_or(0);
                        bytes[at] ^= u.int_in_range(1u8..=255).unwrap_or(1);
                    }
                }
                offered += 1;
                intake.offer(&key("ugv1"), bytes.len(), || bytes.clone());
            }
            3 | 4 => {}
            // Over the size limit: refused without its payload being copied.
            5 => {
                let extra: u16 = u.arbitrary().unwrap_or(1);
                offered += 1;
                intake.offer(&key("ugv1"), LINK_MAX_MESSAGE_BYTES + 1 + usize::from(extra), || {
                    panic!("an oversized payload was copied")
                });
            }
            _ => drain(&intake, &mut base),
        }
    }
    drain(&intake, &mut base);
    let stats = intake.stats();
    assert!(stats.received.keys().all(|k| LINK_MEMBERS.iter().any(|m| m.0 == k)), "{:?}", stats.received);
    let kept: u64 = stats.received.values().map(|c| c.messages).sum::<u64>() + stats.received_unlisted.messages;
    let refused = stats.refused.unknown_sender + stats.refused.oversized + stats.refused.inbox_full;
    assert_eq!(kept + refused, offered, "every message kept or counted");
    assert!(base.table_sizes().peers <= LINK_MEMBERS.len());
}

/// The MCAP log reader, `spomp log check` and `spomp log recover` on arbitrary bytes; a log
/// that recovers must check as closed, with the messages the recovery counted.
pub fn mcap_log(data: &[u8]) {
    let _ = spomp_mcap::McapLog::from_bytes(data.to_vec()).messages();
    let _ = spomp_mcap::check_log(data);
    let mut fixed = std::io::Cursor::new(Vec::new());
    if let Ok(recovered) = spomp_mcap::recover_log(data, &mut fixed) {
        let _ = fixed.flush();
        let check = spomp_mcap::check_log(fixed.get_ref()).expect("a recovered log is an MCAP log");
        assert!(check.closed, "a recovered log is closed: {check:?}");
        assert!(check.intact(), "a recovered log has no corrupt record and every checksum holds: {check:?}");
        assert_eq!(check.messages(), recovered.messages(), "the recovered log has the messages counted");
        let all = spomp_mcap::McapLog::from_bytes(fixed.into_inner()).messages().expect("a recovered log reads");
        assert_eq!(all.len() as u64, recovered.messages());
    }
}

/// The longest stretch of log time the replay target replays, seconds: a replay is linear in
/// the calls, and the fuzzer looks for crashes and hangs, not for long runs.
const MAX_REPLAY_S: f64 = 1.0;

/// `spomp replay` on arbitrary bytes as the log: [`spomp_mcap::open_replay_log`] reads the run's
/// setup (the `spomp.run` metadata with the mission files and settings, the area attachment),
/// then [`spomp_mcap::replay::replay`] rebuilds the first recorded robot from it (the mission
/// files written back into a scratch folder of its own, removed when it ends) and replays up to
/// [`MAX_REPLAY_S`] of its calls. Property: the replay never claims to have got past the log's
/// end, and a replayed robot is one the setup lists.
pub fn replay_log(data: &[u8]) {
    use spomp_mcap::replay::{ReplayOptions, replay};
    let Ok(log) = spomp_mcap::open_replay_log(data) else { return };
    let Some(info) = &log.info else { return };
    let Some(robot) = info.robot_seeds.keys().next() else { return };
    let options = ReplayOptions { robot: robot.clone(), until_s: Some(MAX_REPLAY_S), ..ReplayOptions::default() };
    let registry = spomp_robot::registry();
    if let Ok(report) = replay(data, &options, &registry, &mut |_| {}) {
        assert_eq!(&report.robot, robot);
        assert!(report.replayed_to_s <= report.log_end_s.max(0.0) + 1e-9, "{report:?}");
    }
}

/// The largest panorama the terrain target analyses, pixels (a 10 × 1 MB panorama is slow, not
/// wrong: the fuzzer looks for crashes, and the analysis is linear in the pixels).
const MAX_TERRAIN_PIXELS: usize = 1 << 20;

/// `spomp terrain` input: the bytes are the depth-panorama PNG; it is read with the default
/// range scale and field of view (`--range-scale`, `--v-fov-deg 90`) and analysed with the default
/// and the simulation parameters.
pub fn terrain_input(data: &[u8]) {
    use spomp_local_planner::{TerrainAnalyzer, TerrainParams};
    let v_fov = 90.0f64.to_radians();
    let Ok(depth) = spomp_world::decode_depth_png(data, spomp_core::panorama::DEFAULT_RANGE_SCALE_M, v_fov) else {
        return;
    };
    if depth.geometry.len() > MAX_TERRAIN_PIXELS {
        return;
    }
    for params in [TerrainParams::default(), TerrainParams::simulation()] {
        if let Ok(mut analyzer) = TerrainAnalyzer::new(depth.geometry, params) {
            let _ = analyzer.analyze(&depth);
        }
    }
}

/// The fuzz crate's folder (its `corpus/` and `regressions/`): this file is also compiled into the
/// workspace's integration tests (`tests/it/fuzz_replay.rs`), whose manifest folder is the
/// workspace root.
#[cfg(test)]
fn fuzz_dir() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    if manifest.join("fuzz_targets").is_dir() { manifest.to_path_buf() } else { manifest.join("fuzz") }
}

#[cfg(test)]
mod seeds {
    //! `cargo test -- --ignored write_seeds` writes the hand-made seed inputs of the targets
    //! whose formats a fuzzer cannot easily guess (kept in `corpus/`).

    use spomp_core::{Point2, Pose2, ReachabilityScan, RobotId, Time};
    use spomp_teamstate::{GoalOrigin, TeamState, TeamStateParams, TierSet};

    fn put(target: &str, name: &str, bytes: &[u8]) {
        let dir = super::fuzz_dir().join("corpus").join(target);
        std::fs::create_dir_all(&dir).expect("corpus folder");
        std::fs::write(dir.join(name), bytes).expect("seed");
    }

    #[test]
    #[ignore = "writes the seed inputs into corpus/"]
    fn write_seeds() {
        // A sync message carrying a goal, a pose, a scan and a map version.
        let mut a = TeamState::new(RobotId::new("ugv1"), 1, TeamStateParams::default()).expect("team state");
        let t = Time::from_secs_f64;
        a.identify_goal(Point2::new(1.0, 2.0), GoalOrigin::Detected, t(1.0)).expect("goal");
        a.set_pose(Pose2::new(3.0, 4.0, 0.5), t(1.0)).expect("pose");
        a.add_scan(ReachabilityScan {
            robot: RobotId::new("ugv1"),
            stamp: t(1.0),
            pose: Pose2::new(3.0, 4.0, 0.0),
            range_m: vec![3.5; 16],
            obstacle: vec![false; 16],
        })
        .expect("scan");
        a.add_map_version(1, t(1.0), vec![5; 16]).expect("map");
        let m = a.make_sync(&RobotId::new("ugv2"), TierSet::ALL, usize::MAX).expect("a message");
        put("teamstate_sync", "seed-populated", &m.encode());
        // A depth panorama: 8 rows × 32 columns of ranges, a few with no return.
        let counts: Vec<u16> = (0..8 * 32).map(|i| if i % 11 == 0 { 0 } else { 200 + (i as u16 % 32) * 40 }).collect();
        let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(32, 8, counts).expect("image");
        let mut png = std::io::Cursor::new(Vec::new());
        img.write_to(&mut png, image::ImageFormat::Png).expect("png");
        put("terrain_input", "seed-8x32", png.get_ref());
        // Team-link deliveries (each byte pair picks an operation and its argument): genuine
        // messages and drains; a replay and a flip of one; a stranger's name; an oversized one.
        put("teamlink_receive", "seed-genuine", &[0, 0, 6, 0, 0, 6, 0, 6]);
        put("teamlink_receive", "seed-replay-flip", &[0, 0, 6, 3, 0, 6, 4, 0, 1, 9, 40, 6, 0, 6]);
        put(
            "teamlink_receive",
            "seed-stranger",
            &[2, 8, b'm', b'a', b'l', b'l', b'o', b'r', b'y', b'!', 4, 1, 2, 3, 4, 6],
        );
        put("teamlink_receive", "seed-oversized", &[0, 5, 0, 1, 6, 0, 6]);
    }
}

#[cfg(test)]
mod replay {
    //! Every kept input — the minimised corpora and the inputs of fixed crashes — through its
    //! target, with a plain `cargo test`: a regression panics here.

    fn replay(target: &str, run: fn(&[u8])) {
        let root = super::fuzz_dir();
        let mut count = 0;
        for kind in ["corpus", "regressions"] {
            let Ok(entries) = std::fs::read_dir(root.join(kind).join(target)) else { continue };
            let mut files: Vec<_> = entries.filter_map(Result::ok).map(|e| e.path()).collect();
            files.sort();
            for f in files.into_iter().filter(|f| f.is_file()) {
                let data = std::fs::read(&f).expect("a kept input reads");
                run(&data);
                count += 1;
            }
        }
        assert!(count > 0, "no kept inputs for `{target}`: its corpus is missing");
    }

    #[test]
    fn mission_bytes() {
        replay("mission_bytes", super::mission_bytes);
    }

    #[test]
    fn mission_yaml() {
        replay("mission_yaml", super::mission_yaml);
    }

    #[test]
    fn world() {
        replay("world", super::world);
    }

    #[test]
    fn qgc_plan() {
        replay("qgc_plan", super::qgc_plan);
    }

    #[test]
    fn teamstate_sync() {
        replay("teamstate_sync", super::teamstate_sync);
    }

    #[test]
    fn mcap_log() {
        replay("mcap_log", super::mcap_log);
    }

    #[test]
    fn teamlink_receive() {
        replay("teamlink_receive", super::teamlink_receive);
    }

    #[test]
    fn terrain_input() {
        replay("terrain_input", super::terrain_input);
    }

    #[test]
    fn replay_log() {
        replay("replay_log", super::replay_log);
    }
}
