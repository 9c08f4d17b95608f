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
            None => spomp_behaviors::mission::limits::read_text(p, spomp_behaviors::mission::limits::MAX_SOURCE_BYTES)
                .map_err(|e| ReplayError::Io(e.to_string()))?,
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
    AreaRecord {
        classes: area.classes.clone(),
        grid: area.grid,
        prior_map: area.prior_map.clone(),
        map_origin: area.map_origin,
    }
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

/// A recorded file path, checked: some leading `..` (the file lies that many folders above the
/// mission's) and then plain names only. Anything else (an absolute path, a `..` after a name,
/// `.`, an empty path) is refused, so a crafted log cannot name a file outside the replay's
/// folder: `a/../../victim` has the shape of a path inside and resolves outside.
fn checked_relative(rel: &str) -> Result<(usize, PathBuf), ReplayError> {
    let refuse = |why: &str| ReplayError::Log(format!("file path `{rel}` in the run metadata {why}"));
    let mut ups = 0;
    let mut names = PathBuf::new();
    for c in Path::new(rel).components() {
        match c {
            Component::ParentDir if names.as_os_str().is_empty() => ups += 1,
            Component::ParentDir => return Err(refuse("climbs out of a folder it named (`..` after a name)")),
            Component::Normal(name) => names.push(name),
            Component::CurDir => return Err(refuse("has a `.` component")),
            Component::RootDir | Component::Prefix(_) => return Err(refuse("is absolute")),
        }
    }
    if names.as_os_str().is_empty() {
        return Err(refuse("names no file"));
    }
    Ok((ups, names))
}

/// The mission's files written back into `dir`, a fresh folder of the replay's own (the mission
/// deep enough that every `..` of an include stays inside), loaded and validated. Every path is
/// checked before anything is written, and each file is created new (never through a link,
/// never over another).
pub(crate) fn load_from_info(
    info: &RunInfo,
    dir: &Path,
    registry: &NodeRegistry<RobotRuntime>,
) -> Result<LoadedMission, ReplayError> {
    let checked: Vec<(usize, PathBuf)> =
        info.files.iter().map(|(rel, _)| checked_relative(rel)).collect::<Result<_, _>>()?;
    let depth = checked.iter().map(|(ups, _)| *ups).max().unwrap_or(0);
    let mut mission_dir = dir.to_path_buf();
    for k in 0..depth {
        mission_dir.push(format!("d{k}"));
    }
    let mut mission_path = None;
    for ((ups, names), (_, text)) in checked.iter().zip(&info.files) {
        // `ups` ≤ `depth`: the file's folder is `ups` levels above the mission's, still in `dir`.
        let mut path = dir.to_path_buf();
        for k in 0..depth - ups {
            path.push(format!("d{k}"));
        }
        path.push(names);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| ReplayError::Io(format!("{}: {e}", parent.display())))?;
        }
        let mut file = std::fs::OpenOptions::new().write(true).create_new(true).open(&path).map_err(|e| {
            if e.kind() == std::io::ErrorKind::AlreadyExists {
                ReplayError::Log(format!("the run metadata names file `{}` twice", names.display()))
            } else {
                ReplayError::Io(format!("{}: {e}", path.display()))
            }
        })?;
        std::io::Write::write_all(&mut file, text.as_bytes())
            .map_err(|e| ReplayError::Io(format!("{}: {e}", path.display())))?;
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

#[cfg(test)]
mod tests {
    use super::checked_relative;
    use std::path::PathBuf;

    #[test]
    fn recorded_paths_inside_the_mission_tree_are_kept() {
        assert_eq!(checked_relative("mission.yaml").unwrap(), (0, PathBuf::from("mission.yaml")));
        assert_eq!(checked_relative("subtrees/a.yaml").unwrap(), (0, PathBuf::from("subtrees/a.yaml")));
        assert_eq!(checked_relative("../../lib/x.yaml").unwrap(), (2, PathBuf::from("lib/x.yaml")));
    }

    #[test]
    fn recorded_paths_that_could_leave_the_replay_folder_are_refused() {
        for bad in ["a/../../victim", "a/../b", "x/y/../../../etc/passwd", "/etc/passwd", "./a", "..", ""] {
            assert!(checked_relative(bad).is_err(), "{bad:?} must be refused");
        }
    }
}
