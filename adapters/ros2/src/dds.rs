//! A ROS 2 node over RustDDS: participant set-up (domain, interfaces), typed publishers and
//! subscriptions for the message types of [`spomp_ros_msgs`].

use std::net::IpAddr;

// The participant and its entities need RustDDS: the `dds` feature. The settings above them are
// part of a mission's `ros2:` section and parse without it.
#[cfg(feature = "dds")]
mod node;
#[cfg(feature = "dds")]
pub use node::{DdsNode, latched_qos, rosout_qos, sensor_qos, state_qos};

/// Why the ROS 2 side could not be set up or used.
#[derive(Debug, thiserror::Error)]
pub enum DdsError {
    /// The DDS participant or an entity could not be created.
    #[error("DDS: {0}")]
    Create(String),
    /// A topic or node name ROS 2 does not accept.
    #[error("`{name}` is not a valid ROS 2 name: {reason}")]
    Name {
        /// The name.
        name: String,
        /// Why.
        reason: String,
    },
}

/// Where DDS may talk.
///
/// `interfaces` restricts what is sent and advertised, not what is received: RustDDS (0.15, under
/// ros2-client 0.12) binds its four receive sockets — discovery and user traffic, unicast and
/// multicast — to `0.0.0.0` with no option to choose an address, and filters only the multicast
/// group joins and the locators it advertises. A peer that is told nothing of this robot cannot
/// find it through another interface, but a datagram sent there to its port still arrives.
/// [`RECEIVE_ON_ALL_INTERFACES`] is the notice `spomp run` and `spomp sim --ros2` print; the
/// remedy (a host firewall rule or a network namespace) is in `docs/robots.md`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DdsSettings {
    /// DDS domain id.
    pub domain_id: u16,
    /// Only these local addresses carry multicast discovery and are advertised; empty = all.
    pub interfaces: Vec<IpAddr>,
}

/// What a user restricting DDS to some interfaces must know (see [`DdsSettings`]).
pub const RECEIVE_ON_ALL_INTERFACES: &str = "DDS advertises and sends on the chosen interfaces only, but its receive \
     sockets listen on every interface (RustDDS binds 0.0.0.0); to refuse DDS traffic elsewhere, \
     firewall UDP ports 7400+250·domain … +249 on the other interfaces or run in a network namespace \
     (docs/robots.md, \"DDS interfaces\")";

impl DdsSettings {
    /// The ports of this domain's RTPS traffic (RTPS 2.5 §9.6.2.3: port base 7400, 250 per
    /// domain; discovery and user traffic of up to 120 participants), for a firewall rule.
    pub fn rtps_ports(&self) -> std::ops::RangeInclusive<u32> {
        let base = 7400 + 250 * u32::from(self.domain_id);
        base..=base + 249
    }
}

impl DdsSettings {
    /// A robot's `ros2:` domain and interfaces, then the ROS 2 environment
    /// ([`DdsSettings::with_ros_environment`]).
    pub fn for_robot(spec: &crate::mission_section::Ros2Spec) -> Result<Self, String> {
        let interfaces = spec
            .interfaces
            .iter()
            .map(|a| a.parse::<IpAddr>().map_err(|_| format!("ros2.interfaces: `{a}` is not an IP address")))
            .collect::<Result<Vec<_>, _>>()?;
        DdsSettings { domain_id: spec.domain_id, interfaces }.with_ros_environment()
    }

    /// Applies the ROS 2 environment a launch file or shell sets: `ROS_DOMAIN_ID`, and
    /// `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` / `ROS_LOCALHOST_ONLY=1` (loopback only).
    pub fn with_ros_environment(mut self) -> Result<Self, String> {
        if let Ok(v) = std::env::var("ROS_DOMAIN_ID")
            && !v.trim().is_empty()
        {
            self.domain_id = v
                .trim()
                .parse::<u16>()
                .ok()
                .filter(|d| *d <= 232)
                .ok_or_else(|| format!("ROS_DOMAIN_ID={v}: expected a domain id 0..232"))?;
        }
        let localhost = std::env::var("ROS_AUTOMATIC_DISCOVERY_RANGE")
            .is_ok_and(|v| v.eq_ignore_ascii_case("localhost"))
            || std::env::var("ROS_LOCALHOST_ONLY").is_ok_and(|v| v.trim() == "1");
        if localhost {
            self.interfaces = vec![IpAddr::from([127, 0, 0, 1])];
        }
        Ok(self)
    }
}
