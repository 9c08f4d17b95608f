//! The team's key directory, made by `spomp keys generate MISSION --out DIR`:
//!
//! | file | holds | who needs it |
//! |---|---|---|
//! | `team.json` | the team's name, every robot's and the operator's Ed25519 public key | every robot |
//! | `<robot>.key.json` | that robot's Ed25519 secret key and transport password | that robot only |
//! | `operator.key.json` | the operator's secret key and transport password (issue 37) | the operator's machine, and a robot that serves an operator interface |
//! | `transport.passwords` | every member's `user:password` line (Zenoh's dictionary) | every robot |
//!
//! The operator (reserved id [`OPERATOR_ID`]) is a member like a robot: the transport admits it
//! with its password ([`KeyDir::credentials`]) and it signs with its key ([`KeyDir::security`]);
//! only its key may issue operator commands (`team.json` lists it under `operators`).
//!
//! Secret files are written readable by their owner only (mode 0600), and a secret file that
//! group or others may read or write is refused, as ssh refuses such keys. A robot loads
//! `team.json`, its own key file and the dictionary; a key file of another robot or team is
//! refused.

use std::collections::BTreeMap;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rand::RngCore;
use serde::{Deserialize, Serialize};
use spomp_core::RobotId;
use spomp_teamstate::{OPERATOR_ID, TeamKeys, TeamSecurity};

const TEAM_FORMAT: &str = "spomp-team-keys/1";
const ROBOT_FORMAT: &str = "spomp-robot-key/1";
/// Transport authentication: this robot's user name and password, and the team's dictionary of
/// every member's (Zenoh's user/password authentication: a challenge and an HMAC, so the password
/// never crosses the link).
#[derive(Clone, Debug)]
pub struct Credentials {
    /// This robot's user name.
    pub user: String,
    /// This robot's password.
    pub password: String,
    /// A file of `user:password` lines, one per member: whom this robot accepts.
    pub dictionary_file: std::path::PathBuf,
}

/// The team's public keys.
pub const TEAM_FILE: &str = "team.json";
/// Zenoh's user/password dictionary.
pub const PASSWORDS_FILE: &str = "transport.passwords";
/// Key files are a few hundred bytes; anything much larger is not one.
const MAX_KEY_FILE_BYTES: u64 = 1 << 20;

/// Why a key directory could not be made or read.
#[derive(Debug, thiserror::Error)]
pub enum KeyDirError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A file is not what it should be.
    #[error("{path}: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong and what was expected.
        reason: String,
    },
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TeamFile {
    format: String,
    team: String,
    /// Robot id → public key (64 hex digits).
    members: BTreeMap<String, String>,
    /// Operator id → public key (64 hex digits): members whose key issues operator commands.
    /// Absent in key directories made before operators existed.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    operators: BTreeMap<String, String>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RobotFile {
    format: String,
    team: String,
    robot: String,
    /// Ed25519 secret key, 64 hex digits.
    secret_key: String,
    /// Transport password, hex.
    password: String,
}

/// One robot's secrets.
#[derive(Clone)]
pub struct RobotKeys {
    /// The robot.
    pub robot: RobotId,
    /// Its Ed25519 secret key.
    pub secret_key: [u8; 32],
    /// Its transport password.
    pub password: String,
}

impl std::fmt::Debug for RobotKeys {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RobotKeys").field("robot", &self.robot).finish_non_exhaustive()
    }
}

/// A loaded key directory: the team's public keys, and where its files are.
#[derive(Clone, Debug)]
pub struct KeyDir {
    dir: PathBuf,
    team: String,
    /// The robots' public keys.
    members: BTreeMap<RobotId, [u8; 32]>,
    /// The operators' public keys.
    operators: BTreeMap<RobotId, [u8; 32]>,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> KeyDirError + '_ {
    move |source| KeyDirError::Io { path: path.to_path_buf(), source }
}

fn invalid(path: &Path, reason: impl Into<String>) -> KeyDirError {
    KeyDirError::Invalid { path: path.to_path_buf(), reason: reason.into() }
}

/// Reads a small key-directory file; a `secret` one only if no one but its owner may read or
/// write it.
fn read_small(path: &Path, secret: bool) -> Result<String, KeyDirError> {
    let meta = fs::metadata(path).map_err(io(path))?;
    if !meta.is_file() {
        return Err(invalid(path, "not a regular file"));
    }
    #[cfg(unix)]
    if secret {
        use std::os::unix::fs::PermissionsExt;
        let mode = meta.permissions().mode() & 0o777;
        if mode & 0o077 != 0 {
            return Err(invalid(
                path,
                format!(
                    "mode {mode:04o}: a secret file others may read or change is refused; make it readable by its owner only: chmod 600 {}",
                    path.display()
                ),
            ));
        }
    }
    #[cfg(not(unix))]
    let _ = secret;
    if meta.len() > MAX_KEY_FILE_BYTES {
        return Err(invalid(path, format!("{} bytes; a key file is at most {MAX_KEY_FILE_BYTES}", meta.len())));
    }
    fs::read_to_string(path).map_err(io(path))
}

fn key_from_hex(path: &Path, what: &str, text: &str) -> Result<[u8; 32], KeyDirError> {
    let bytes = hex::decode(text).map_err(|e| invalid(path, format!("{what}: expected 64 hex digits ({e})")))?;
    <[u8; 32]>::try_from(bytes.as_slice())
        .map_err(|_| invalid(path, format!("{what}: expected 64 hex digits, found {}", text.len())))
}

/// Writes `text` to `path`, readable by the owner only when `secret`.
fn write_file(path: &Path, text: &str, secret: bool) -> Result<(), KeyDirError> {
    let mut options = fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    if secret {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    #[cfg(not(unix))]
    let _ = secret;
    let mut f = options.open(path).map_err(io(path))?;
    f.write_all(text.as_bytes()).map_err(io(path))?;
    f.sync_all().map_err(io(path))
}

fn is_identifier(s: &str) -> bool {
    !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

impl KeyDir {
    /// Makes a key directory for `team` with one key pair and password per robot in `robots`,
    /// and one for the operator ([`OPERATOR_ID`]). `dir` must not hold keys already (nothing is
    /// overwritten).
    pub fn generate(dir: &Path, team: &str, robots: &[RobotId]) -> Result<KeyDir, KeyDirError> {
        for r in robots {
            if !is_identifier(r.as_str()) {
                return Err(invalid(dir, format!("robot id `{r}` is not an identifier ([A-Za-z0-9_-])")));
            }
            if r.as_str() == OPERATOR_ID {
                return Err(invalid(dir, format!("robot id `{r}` is reserved for the team's operator")));
            }
        }
        fs::create_dir_all(dir).map_err(io(dir))?;
        let team_path = dir.join(TEAM_FILE);
        if team_path.exists() {
            return Err(invalid(&team_path, "already exists; keys are never overwritten (choose another --out)"));
        }
        let mut rng = rand::rng();
        let mut members = BTreeMap::new();
        let mut operators = BTreeMap::new();
        let mut passwords = String::new();
        let operator = RobotId::new(OPERATOR_ID);
        for robot in robots.iter().chain(std::iter::once(&operator)) {
            let mut secret = [0u8; 32];
            rng.fill_bytes(&mut secret);
            let mut pw = [0u8; 24];
            rng.fill_bytes(&mut pw);
            let password = hex::encode(pw);
            let file = RobotFile {
                format: ROBOT_FORMAT.into(),
                team: team.into(),
                robot: robot.to_string(),
                secret_key: hex::encode(secret),
                password: password.clone(),
            };
            let text = serde_json::to_string_pretty(&file).map_err(|e| invalid(dir, e.to_string()))?;
            write_file(&dir.join(format!("{robot}.key.json")), &(text + "\n"), true)?;
            passwords.push_str(&format!("{robot}:{password}\n"));
            let public = TeamSecurity::public_key_of(&secret);
            match robot == &operator {
                true => operators.insert(robot.clone(), public),
                false => members.insert(robot.clone(), public),
            };
        }
        write_file(&dir.join(PASSWORDS_FILE), &passwords, true)?;
        let file = TeamFile {
            format: TEAM_FORMAT.into(),
            team: team.into(),
            members: members.iter().map(|(r, k)| (r.to_string(), hex::encode(k))).collect(),
            operators: operators.iter().map(|(r, k)| (r.to_string(), hex::encode(k))).collect(),
        };
        let text = serde_json::to_string_pretty(&file).map_err(|e| invalid(dir, e.to_string()))?;
        write_file(&team_path, &(text + "\n"), false)?;
        Ok(KeyDir { dir: dir.to_path_buf(), team: team.into(), members, operators })
    }

    /// Reads the team's public keys from `dir/team.json`.
    pub fn load(dir: &Path) -> Result<KeyDir, KeyDirError> {
        let path = dir.join(TEAM_FILE);
        let text = read_small(&path, false)?;
        let file: TeamFile = serde_json::from_str(&text).map_err(|e| {
            invalid(&path, format!("{e}; expected {{\"format\": \"{TEAM_FORMAT}\", \"team\": NAME, \"members\": {{ROBOT: PUBLIC_KEY_HEX}}}}"))
        })?;
        if file.format != TEAM_FORMAT {
            return Err(invalid(&path, format!("format `{}`, expected `{TEAM_FORMAT}`", file.format)));
        }
        let mut members = BTreeMap::new();
        for (robot, key) in &file.members {
            if robot == OPERATOR_ID {
                return Err(invalid(
                    &path,
                    format!("`{OPERATOR_ID}` is listed as a robot; it belongs under `operators`"),
                ));
            }
            members.insert(RobotId::new(robot), key_from_hex(&path, &format!("public key of {robot}"), key)?);
        }
        let mut operators = BTreeMap::new();
        for (op, key) in &file.operators {
            if file.members.contains_key(op) {
                return Err(invalid(&path, format!("`{op}` is listed both as a robot and as an operator")));
            }
            operators.insert(RobotId::new(op), key_from_hex(&path, &format!("public key of operator {op}"), key)?);
        }
        Ok(KeyDir { dir: dir.to_path_buf(), team: file.team, members, operators })
    }

    /// The team's name.
    pub fn team(&self) -> &str {
        &self.team
    }

    /// The members: every robot and operator, in id order (who the transport admits).
    pub fn members(&self) -> impl Iterator<Item = &RobotId> {
        let mut all: Vec<&RobotId> = self.members.keys().chain(self.operators.keys()).collect();
        all.sort();
        all.into_iter()
    }

    /// The robots (members that are not operators), in id order.
    pub fn robots(&self) -> impl Iterator<Item = &RobotId> {
        self.members.keys()
    }

    /// The operators, in id order (one, [`OPERATOR_ID`], in a generated directory; none in one
    /// made before operators existed).
    pub fn operators(&self) -> impl Iterator<Item = &RobotId> {
        self.operators.keys()
    }

    /// The team's public keys, for checking signatures (the operators marked as such).
    pub fn team_keys(&self) -> Result<TeamKeys, KeyDirError> {
        let mut keys = TeamKeys::new(self.team.clone());
        for (robot, key) in &self.members {
            keys.add(robot.clone(), key)
                .map_err(|e| invalid(&self.dir.join(TEAM_FILE), format!("public key of {robot}: {e}")))?;
        }
        for (op, key) in &self.operators {
            keys.add_operator(op.clone(), key)
                .map_err(|e| invalid(&self.dir.join(TEAM_FILE), format!("public key of operator {op}: {e}")))?;
        }
        Ok(keys)
    }

    /// What the operator signs commands with: its secret key (`operator.key.json`) and the
    /// team's public keys. A short-lived operator member sets it as its team state's security;
    /// a robot that serves an operator interface passes it to
    /// [`spomp_teamstate::TeamState::issue_command_as`].
    pub fn operator_security(&self) -> Result<TeamSecurity, KeyDirError> {
        self.security(&RobotId::new(OPERATOR_ID))
    }

    /// The operator's transport credentials (user [`OPERATOR_ID`], its password, the team's
    /// dictionary): the operator opens the team link with these like a robot.
    pub fn operator_credentials(&self) -> Result<Credentials, KeyDirError> {
        self.credentials(&RobotId::new(OPERATOR_ID))
    }

    /// Reads `robot`'s secrets from `dir/<robot>.key.json` (the operator's: `operator.key.json`).
    pub fn robot_keys(&self, robot: &RobotId) -> Result<RobotKeys, KeyDirError> {
        let path = self.dir.join(format!("{}.key.json", robot));
        let text = read_small(&path, true)?;
        let file: RobotFile = serde_json::from_str(&text).map_err(|e| invalid(&path, e.to_string()))?;
        if file.format != ROBOT_FORMAT {
            return Err(invalid(&path, format!("format `{}`, expected `{ROBOT_FORMAT}`", file.format)));
        }
        if file.robot != robot.as_str() || file.team != self.team {
            return Err(invalid(
                &path,
                format!(
                    "the key of robot `{}` of team `{}`, not of `{robot}` of `{}`",
                    file.robot, file.team, self.team
                ),
            ));
        }
        let secret_key = key_from_hex(&path, "secret_key", &file.secret_key)?;
        Ok(RobotKeys { robot: robot.clone(), secret_key, password: file.password })
    }

    /// What `robot` signs and checks with: its secret key and the team's public keys.
    pub fn security(&self, robot: &RobotId) -> Result<TeamSecurity, KeyDirError> {
        let keys = self.robot_keys(robot)?;
        TeamSecurity::new(robot.clone(), &keys.secret_key, Arc::new(self.team_keys()?))
            .map_err(|e| invalid(&self.dir.join(format!("{robot}.key.json")), e.to_string()))
    }

    /// `robot`'s transport credentials (its password and the team's dictionary).
    pub fn credentials(&self, robot: &RobotId) -> Result<Credentials, KeyDirError> {
        let keys = self.robot_keys(robot)?;
        let dictionary_file = self.dir.join(PASSWORDS_FILE);
        read_small(&dictionary_file, true)?;
        Ok(Credentials { user: robot.to_string(), password: keys.password, dictionary_file })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_generated_directory_loads_and_each_robot_signs_for_itself_only() {
        let dir = std::env::temp_dir().join(format!("spomp-keys-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        let robots = [RobotId::new("ugv1"), RobotId::new("uav1")];
        KeyDir::generate(&dir, "city", &robots).unwrap();
        assert!(KeyDir::generate(&dir, "city", &robots).is_err(), "never overwrites");
        let keys = KeyDir::load(&dir).unwrap();
        assert_eq!(keys.robots().count(), 2);
        assert_eq!(keys.members().count(), 3, "the robots and the operator");
        let sec = keys.security(&RobotId::new("ugv1")).unwrap();
        assert_eq!(sec.robot().as_str(), "ugv1");
        assert!(keys.credentials(&RobotId::new("uav1")).unwrap().password.len() >= 32);
        // ugv1's file presented as uav1's.
        fs::copy(dir.join("ugv1.key.json"), dir.join("uav2.key.json")).unwrap();
        let err = keys.robot_keys(&RobotId::new("uav2")).unwrap_err().to_string();
        assert!(err.contains("not of `uav2`"), "{err}");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = fs::metadata(dir.join("ugv1.key.json")).unwrap().permissions().mode();
            assert_eq!(mode & 0o077, 0, "secret key readable by others: {mode:o}");
        }
        fs::write(dir.join(TEAM_FILE), "{\"format\": 1}").unwrap();
        let err = KeyDir::load(&dir).unwrap_err().to_string();
        assert!(err.contains("team.json") && err.contains("expected"), "{err}");
        let _ = fs::remove_dir_all(&dir);
    }

    /// Issue 37: the operator's key pair is generated beside the robots', loaded as an operator
    /// (only its key issues commands), and the transport admits it like a robot.
    #[test]
    fn the_operator_key_is_generated_loaded_and_admitted() {
        let dir = std::env::temp_dir().join(format!("spomp-keys-op-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        let robots = [RobotId::new("ugv1"), RobotId::new("uav1")];
        KeyDir::generate(&dir, "city", &robots).unwrap();
        let keys = KeyDir::load(&dir).unwrap();
        let operator = RobotId::new(OPERATOR_ID);
        assert_eq!(keys.robots().cloned().collect::<Vec<_>>(), vec![RobotId::new("uav1"), RobotId::new("ugv1")]);
        assert_eq!(keys.operators().collect::<Vec<_>>(), vec![&operator]);
        assert!(keys.members().any(|m| m == &operator), "the transport's roster admits the operator");
        let team = keys.team_keys().unwrap();
        assert!(team.is_operator(&operator) && !team.is_operator(&RobotId::new("ugv1")));
        assert_eq!(keys.operator_security().unwrap().robot(), &operator);
        let credentials = keys.operator_credentials().unwrap();
        assert_eq!(credentials.user, OPERATOR_ID);
        let dictionary = fs::read_to_string(dir.join(PASSWORDS_FILE)).unwrap();
        assert!(dictionary.lines().any(|l| l == format!("{OPERATOR_ID}:{}", credentials.password)));
        let _ = fs::remove_dir_all(&dir);
        // A robot may not take the operator's id.
        let err = KeyDir::generate(&dir, "city", &[operator]).unwrap_err().to_string();
        assert!(err.contains("reserved"), "{err}");
        let _ = fs::remove_dir_all(&dir);
    }

    /// Regression (issue 36): key files anyone could read were taken without a word.
    #[cfg(unix)]
    #[test]
    fn secret_files_others_may_read_are_refused_with_the_fix() {
        use std::os::unix::fs::PermissionsExt;
        let dir = std::env::temp_dir().join(format!("spomp-keys-mode-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        let ugv1 = RobotId::new("ugv1");
        let keys = KeyDir::generate(&dir, "city", std::slice::from_ref(&ugv1)).unwrap();
        let mode = |name: &str| fs::metadata(dir.join(name)).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode("ugv1.key.json"), 0o600);
        assert_eq!(mode(PASSWORDS_FILE), 0o600);
        let chmod = |name: &str, m: u32| fs::set_permissions(dir.join(name), fs::Permissions::from_mode(m)).unwrap();
        for wide in [0o644, 0o640, 0o604, 0o620, 0o666] {
            chmod("ugv1.key.json", wide);
            let err = keys.security(&ugv1).unwrap_err().to_string();
            assert!(err.contains("ugv1.key.json") && err.contains("chmod 600"), "{wide:o}: {err}");
            assert!(keys.credentials(&ugv1).is_err(), "{wide:o}");
        }
        chmod("ugv1.key.json", 0o400);
        assert!(keys.security(&ugv1).is_ok(), "owner-only modes are fine");
        chmod(PASSWORDS_FILE, 0o644);
        let err = keys.credentials(&ugv1).unwrap_err().to_string();
        assert!(err.contains(PASSWORDS_FILE) && err.contains("chmod 600"), "{err}");
        chmod(PASSWORDS_FILE, 0o600);
        assert!(keys.credentials(&ugv1).is_ok());
        // The public keys may be read by anyone.
        chmod(TEAM_FILE, 0o644);
        assert!(KeyDir::load(&dir).is_ok());
        let _ = fs::remove_dir_all(&dir);
    }
}
