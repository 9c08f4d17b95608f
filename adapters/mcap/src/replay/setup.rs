//! The run's setup as a log stores it, and back: the mission's files, the seeds, the operating
//! area.

use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};

use crate::{AreaRecord, RunInfo};
use spomp_behaviors::BbValue;
use spomp_behaviors::NodeRegistry;
use spomp_behaviors::mission::compile::{Ir, IrBinding, IrKind};
use spomp_behaviors::mission::{LoadOptions, LoadedMission, load_mission_with};
use spomp_mapping::PngLevel;
use spomp_robot::{OperatingArea, RobotRuntime, robot_seed};

use super::ReplayError;

/// The files a loaded mission is made of: the mission, its includes, and every file a `*_file`
/// port names (plan files), as (path relative to the mission's folder, text).
pub fn mission_files(loaded: &LoadedMission) -> Result<Vec<(String, String)>, ReplayError> {
    let base = loaded.base_dir();
    let mut paths: Vec<PathBuf> = loaded.files.clone();
    for role in loaded.roles.values() {
        file_ports(&role.tree, &base, &mut paths);
    }
    let base = canonical(&base)?;
    let mut out: Vec<(String, String)> = Vec::new();
    for (k, p) in paths.iter().enumerate() {
        let text = match loaded.sources.get(k) {
            Some(t) => t.clone(),
            None => std::fs::read_to_string(p).map_err(|e| ReplayError::Io(format!("{}: {e}", p.display())))?,
        };
        let rel = relative(&base, &canonical(p)?);
        let rel = rel.to_string_lossy().replace('\\', "/");
        if !out.iter().any(|(r, _)| *r == rel) {
            out.push((rel, text));
        }
    }
    Ok(out)
}

fn canonical(p: &Path) -> Result<PathBuf, ReplayError> {
    std::fs::canonicalize(if p.as_os_str().is_empty() { Path::new(".") } else { p })
        .map_err(|e| ReplayError::Io(format!("{}: {e}", p.display())))
}

/// `file` relative to `base` (both absolute), with `..` where it is outside.
fn relative(base: &Path, file: &Path) -> PathBuf {
    let b: Vec<Component<'_>> = base.components().collect();
    let f: Vec<Component<'_>> = file.components().collect();
    let common = b.iter().zip(&f).take_while(|(x, y)| x == y).count();
    let mut out = PathBuf::new();
    for _ in common..b.len() {
        out.push("..");
    }
    for c in &f[common..] {
        out.push(c.as_os_str());
    }
    out
}

fn file_ports(ir: &Ir, base: &Path, out: &mut Vec<PathBuf>) {
    match &ir.kind {
        IrKind::Control { children, .. } => children.iter().for_each(|c| file_ports(c, base, out)),
        IrKind::Decorator { child, .. } => file_ports(child, base, out),
        IrKind::StateMachine { states, .. } => {
            states.iter().filter_map(|s| s.run.as_ref()).for_each(|r| file_ports(r, base, out))
        }
        IrKind::Leaf { ports } => {
            for p in ports {
                if let (true, IrBinding::Literal(BbValue::Str(s))) = (p.spec.name.ends_with("_file"), &p.binding) {
                    let path = Path::new(&**s);
                    let path = if path.is_relative() { base.join(path) } else { path.to_path_buf() };
                    if path.is_file() && !out.contains(&path) {
                        out.push(path);
                    }
                }
            }
        }
    }
}

/// Name of a PNG effort as logs store it.
pub fn png_level_name(level: PngLevel) -> &'static str {
    match level {
        PngLevel::Fast => "fast",
        PngLevel::Default => "default",
        PngLevel::Best => "best",
    }
}

pub(crate) fn png_level(name: &str) -> Result<PngLevel, ReplayError> {
    match name {
        "fast" => Ok(PngLevel::Fast),
        "default" => Ok(PngLevel::Default),
        "best" => Ok(PngLevel::Best),
        other => Err(ReplayError::Log(format!("unknown map compression `{other}` in the run metadata"))),
    }
}

/// The operating area as a log stores it.
pub fn area_record(area: &OperatingArea) -> AreaRecord {
    AreaRecord { classes: area.classes.clone(), grid: area.grid, prior_map: area.prior_map.clone() }
}

/// Everything a replay needs about a run, for the recorder: `source` is what runs it (`sim`,
/// `run`), the seeds those every robot of the mission was set up with ([`robot_seed`]).
pub fn run_info(
    loaded: &LoadedMission,
    source: &str,
    run_seed: u64,
    area: &OperatingArea,
    map_publish_period_s: f64,
    map_compression: PngLevel,
) -> Result<RunInfo, ReplayError> {
    let mission = loaded.mission.as_ref().ok_or_else(|| ReplayError::Mission("the mission did not load".into()))?;
    let robot_seeds: BTreeMap<String, u64> =
        mission.team.iter().enumerate().map(|(i, r)| (r.id.clone(), robot_seed(run_seed, i))).collect();
    Ok(RunInfo {
        spomp_version: env!("CARGO_PKG_VERSION").to_string(),
        source: source.to_string(),
        run_seed,
        robot_seeds,
        files: mission_files(loaded)?,
        map_publish_period_s,
        map_compression: png_level_name(map_compression).to_string(),
        area: area_record(area),
        background_skills: false,
        team_session: 0,
        team_secured: false,
    })
}

/// The mission's files written back into `dir` (the mission deep enough that every `..` of an
/// include stays inside), loaded and validated.
pub(crate) fn load_from_info(
    info: &RunInfo,
    dir: &Path,
    registry: &NodeRegistry<RobotRuntime>,
) -> Result<LoadedMission, ReplayError> {
    let depth = info
        .files
        .iter()
        .map(|(p, _)| Path::new(p).components().take_while(|c| *c == Component::ParentDir).count())
        .max()
        .unwrap_or(0);
    let mut mission_dir = dir.to_path_buf();
    for k in 0..depth {
        mission_dir.push(format!("d{k}"));
    }
    let mut mission_path = None;
    for (rel, text) in &info.files {
        let rel = Path::new(rel);
        if rel.is_absolute() || rel.components().any(|c| matches!(c, Component::Prefix(_) | Component::RootDir)) {
            return Err(ReplayError::Log(format!("file path `{}` in the run metadata is absolute", rel.display())));
        }
        let path = mission_dir.join(rel);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| ReplayError::Io(format!("{}: {e}", parent.display())))?;
        }
        std::fs::write(&path, text).map_err(|e| ReplayError::Io(format!("{}: {e}", path.display())))?;
        mission_path.get_or_insert(path);
    }
    let path = mission_path.ok_or_else(|| ReplayError::Log("the run metadata holds no mission file".into()))?;
    let loaded = load_mission_with(&path, registry, &LoadOptions { allowed_dirs: vec![dir.to_path_buf()] });
    if !loaded.is_valid() {
        let first = loaded.diagnostics.first().map(|d| d.message.clone()).unwrap_or_default();
        return Err(ReplayError::Mission(format!(
            "the recorded mission does not validate with this spomp ({} problems; first: {first})",
            loaded.diagnostics.len()
        )));
    }
    Ok(loaded)
}
