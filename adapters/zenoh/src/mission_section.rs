//! The robot's `team_link:` section of a mission, owned by this adapter (the team link of
//! `spomp run` between robot processes): its settings and rules, registered with the mission
//! language by [`TeamLinkSpec`]'s [`MissionSection`] impl (fields documented in this crate's
//! README).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_behaviors::mission::{MissionSection, SectionContext};

/// How a robot's `spomp run` process meets its teammates (Zenoh endpoints; see docs/robots.md).
#[derive(Debug, Clone, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TeamLinkSpec {
    /// Endpoints this robot listens on, `tcp/HOST:PORT` (e.g. `tcp/0.0.0.0:7447` on the radio).
    #[serde(default)]
    pub listen: Vec<String>,
    /// Endpoints of teammates it connects to, `tcp/HOST:PORT`.
    #[serde(default)]
    pub connect: Vec<String>,
    /// Also find teammates by UDP multicast scouting (off: multicast reaches the whole network).
    #[serde(default)]
    pub multicast_scouting: bool,
}

impl MissionSection for TeamLinkSpec {
    const NAME: &'static str = "team_link";

    fn check(&self, _: &SectionContext<'_>, bad: &mut dyn FnMut(&[&str], String)) {
        for (field, list) in [("listen", &self.listen), ("connect", &self.connect)] {
            for (k, e) in list.iter().enumerate() {
                if let Err(why) = check_endpoint(e) {
                    bad(&[field, &k.to_string()], why);
                }
            }
        }
    }
}

/// Checks a team-link endpoint: `tcp/HOST:PORT` with a port in 1..=65535.
pub fn check_endpoint(e: &str) -> Result<(), String> {
    let expected = || format!("expected an endpoint `tcp/HOST:PORT`, found `{e}`");
    let rest = e.strip_prefix("tcp/").ok_or_else(expected)?;
    let (host, port) = rest.rsplit_once(':').ok_or_else(expected)?;
    match port.parse::<u16>() {
        Ok(p) if p > 0 && !host.is_empty() => Ok(()),
        _ => Err(expected()),
    }
}
