//! The team link between robot processes (docs/design.md §6 "Team link"): the team-state sync
//! messages of `spomp-teamstate` carried between `spomp run` processes over Zenoh, with
//! transport authentication, per-tier priorities and the team's key directory; and the state
//! file a robot resumes from after a reboot.
//!
//! - [`link`]: a robot's Zenoh session ([`TeamLink`]): send per peer and tier, receive, who is
//!   reachable now (liveliness), byte counts.
//! - [`keys`]: the team's key directory (`spomp keys generate`): one Ed25519 signing key and one
//!   transport password per robot, the team's public keys and password dictionary.
//! - [`state_file`]: write a robot's state atomically (write, fsync, rename) and read it back,
//!   refusing damaged files.

//!
//! Without the `link` feature (on by default) the crate keeps what needs no network: the key
//! directory, the state file and the `team_link:` section of a mission. The Zenoh session needs
//! the feature (Zenoh is about a sixth of a release build of `spomp`).

pub mod keys;
#[cfg(feature = "link")]
pub mod link;
pub mod mission_section;
pub mod state_file;

pub use keys::{Credentials, KeyDir, KeyDirError, RobotKeys};
#[cfg(feature = "link")]
pub use link::{Intake, LinkConfig, LinkError, LinkStats, MAX_UNLISTED_SENDERS, Refusals, TeamLink, TierCounts};
pub use mission_section::{TeamLinkSpec, check_endpoint};
pub use state_file::{StateFileError, read_state, write_state};
