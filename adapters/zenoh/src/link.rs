//! A robot's end of the team link: one Zenoh peer session, one key expression per directed link
//! and tier, liveliness tokens for who is reachable now.
//!
//! Key expressions (the team's name and robot ids reduced to `[A-Za-z0-9_-]`):
//! - `spomp/<team>/team/<to>/<from>/<tier>` carries `from`'s sync messages to `to`; the tier
//!   (`coordination`, `scans`, `maps`) picks the Zenoh priority, so a map blob never holds up a
//!   claim on a congested link;
//! - `spomp/<team>/alive/<robot>` is each robot's liveliness token.
//!
//! Nothing here blocks its caller: sends go through a bounded queue to a sender thread (a full
//! queue drops the message, which the sync protocol resends once acknowledgements show the
//! gap), and received messages wait in a bounded inbox until [`TeamLink::receive`] takes them.

use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;

use serde::Serialize;
use spomp_core::RobotId;
use spomp_teamstate::Tier;
use zenoh::Wait;
use zenoh::sample::SampleKind;

use crate::keys::Credentials;

/// How a robot joins the team link.
#[derive(Clone, Debug)]
pub struct LinkConfig {
    /// The team's name (the mission's): robots of other teams on the same network never meet.
    pub team: String,
    /// This robot.
    pub robot: RobotId,
    /// Zenoh endpoints this robot listens on, e.g. `tcp/127.0.0.1:7501`.
    pub listen: Vec<String>,
    /// Zenoh endpoints of peers this robot connects to.
    pub connect: Vec<String>,
    /// Find peers by UDP multicast scouting too (off unless asked: multicast on a real network
    /// reaches everything on it).
    pub multicast_scouting: bool,
    /// Transport authentication; None admits any peer (signatures still guard the state).
    pub credentials: Option<Credentials>,
    /// Largest message accepted from a peer, bytes (larger ones are dropped and counted).
    pub max_message_bytes: usize,
    /// Messages kept waiting, each way, before new ones are dropped (and counted).
    pub queue_messages: usize,
    /// The team: the only senders whose messages are taken and whose liveliness is tracked (the
    /// key directory's members, or the mission's robots). A message naming anyone else is
    /// refused and counted before anything is kept of it. None takes any sender and tracks at
    /// most [`MAX_UNLISTED_SENDERS`] of them by name.
    pub members: Option<BTreeSet<RobotId>>,
}

/// Without a member list ([`LinkConfig::members`]), how many senders (and liveliness tokens)
/// are tracked by name; the rest are counted together.
pub const MAX_UNLISTED_SENDERS: usize = 64;

impl LinkConfig {
    /// A config for `robot` of `team` with the defaults: no endpoints, no scouting, no
    /// authentication, 16 MiB messages, 256 queued messages, any sender taken.
    pub fn new(team: &str, robot: RobotId) -> Self {
        LinkConfig {
            team: team.to_string(),
            robot,
            listen: Vec::new(),
            connect: Vec::new(),
            multicast_scouting: false,
            credentials: None,
            max_message_bytes: 16 * 1024 * 1024,
            queue_messages: 256,
            members: None,
        }
    }
}

/// Why the link could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// Zenoh refused the configuration or could not open the session.
    #[error("team link: {0}")]
    Zenoh(String),
    /// A bad setting.
    #[error("team link: {0}")]
    Config(String),
}

fn zenoh_err(e: impl std::fmt::Display) -> LinkError {
    LinkError::Zenoh(e.to_string())
}

/// Counts of one directed link and tier.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct TierCounts {
    /// Messages handed to Zenoh.
    pub messages: u64,
    /// Their bytes.
    pub bytes: u64,
    /// Messages dropped because the send queue was full.
    pub dropped: u64,
    /// Bytes per second since the link opened (filled in by [`TeamLink::stats`]).
    pub bytes_per_s: f64,
}

/// Received messages refused by the link itself, before anything was kept of them, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Refusals {
    /// The key expression named a sender outside [`LinkConfig::members`].
    pub unknown_sender: u64,
    /// Larger than [`LinkConfig::max_message_bytes`].
    pub oversized: u64,
    /// The inbox held [`LinkConfig::queue_messages`] already.
    pub inbox_full: u64,
}

impl Refusals {
    /// The counts by reason, as the rejection counters name them.
    pub fn by_reason(&self) -> [(&'static str, u64); 3] {
        [("unknown_sender", self.unknown_sender), ("oversized", self.oversized), ("inbox_full", self.inbox_full)]
    }
}

/// What crossed the link so far.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LinkStats {
    /// Sent, per peer and tier (`coordination`, `scans`, `maps`): peers this robot chose.
    pub sent: BTreeMap<String, BTreeMap<&'static str, TierCounts>>,
    /// Received messages and bytes per sender: members only (or, without a member list, the
    /// first [`MAX_UNLISTED_SENDERS`] senders).
    pub received: BTreeMap<String, TierCounts>,
    /// Received from senders beyond [`MAX_UNLISTED_SENDERS`] (no member list), all together.
    pub received_unlisted: TierCounts,
    /// Received messages refused by the link, by reason.
    pub refused: Refusals,
    /// Wall-clock seconds since the link opened.
    pub elapsed_s: f64,
}

/// The name of a tier in key expressions and statistics.
pub fn tier_name(tier: Tier) -> &'static str {
    match tier {
        Tier::Coordination => "coordination",
        Tier::Scans => "scans",
        Tier::Maps => "maps",
    }
}

/// `s` reduced to what a key-expression chunk may hold here: `[A-Za-z0-9_-]`, never empty.
pub fn key_chunk(s: &str) -> String {
    let out: String =
        s.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect();
    if out.is_empty() { "_".into() } else { out }
}

struct Outgoing {
    key: String,
    peer: String,
    tier: Tier,
    bytes: Vec<u8>,
}

#[derive(Default)]
struct Inbox {
    messages: VecDeque<(RobotId, Vec<u8>)>,
}

/// Who may send: the members by their key-expression chunk, or anyone.
#[derive(Clone)]
struct Roster(Option<BTreeMap<String, RobotId>>);

impl Roster {
    fn new(members: Option<&BTreeSet<RobotId>>) -> Roster {
        Roster(members.map(|m| m.iter().map(|r| (key_chunk(r.as_str()), r.clone())).collect()))
    }

    /// The sender a key-expression chunk names, if it may send; never keeps anything of it.
    fn admit(&self, chunk: &str) -> Option<RobotId> {
        match &self.0 {
            Some(members) => members.get(chunk).cloned(),
            None => Some(RobotId::new(chunk)),
        }
    }

    fn listed(&self) -> bool {
        self.0.is_some()
    }
}

/// The receiving half of a link without the transport: what the link does with each message
/// Zenoh delivers (refuse and count, or keep in the bounded inbox), and the inbox
/// [`TeamLink::receive`] drains. Public so that tests and the fuzz target drive the same code
/// with any key expression and payload.
pub struct Intake {
    roster: Roster,
    max_message_bytes: usize,
    queue_messages: usize,
    inbox: Mutex<Inbox>,
    stats: Mutex<LinkStats>,
}

impl Intake {
    /// The intake of a link opened with `config` (its members, size limit and queue length).
    pub fn new(config: &LinkConfig) -> Intake {
        Intake {
            roster: Roster::new(config.members.as_ref()),
            max_message_bytes: config.max_message_bytes,
            queue_messages: config.queue_messages,
            inbox: Mutex::new(Inbox::default()),
            stats: Mutex::new(LinkStats::default()),
        }
    }

    /// Takes one message that arrived on key expression `key` (`…/team/<to>/<from>/<tier>`)
    /// with a payload of `len` bytes, which `payload` copies out: refused and counted unless
    /// its sender may send, it fits the size limit and the inbox has room. Nothing of a refused
    /// message is kept, and its payload is not copied.
    pub fn offer(&self, key: &str, len: usize, payload: impl FnOnce() -> Vec<u8>) {
        let chunk = key.rsplit('/').nth(1).unwrap_or("");
        let Some(from) = self.roster.admit(chunk) else {
            lock(&self.stats).refused.unknown_sender += 1;
            return;
        };
        if len > self.max_message_bytes {
            lock(&self.stats).refused.oversized += 1;
            return;
        }
        let mut stats = lock(&self.stats);
        let mut inbox = lock(&self.inbox);
        if inbox.messages.len() >= self.queue_messages {
            stats.refused.inbox_full += 1;
            return;
        }
        let tracked = self.roster.listed()
            || stats.received.len() < MAX_UNLISTED_SENDERS
            || stats.received.contains_key(from.as_str());
        let counts =
            if tracked { stats.received.entry(from.to_string()).or_default() } else { &mut stats.received_unlisted };
        counts.messages += 1;
        counts.bytes += len as u64;
        inbox.messages.push_back((from, payload()));
    }

    /// The messages kept since the last call, oldest first, with their senders.
    pub fn take(&self) -> Vec<(RobotId, Vec<u8>)> {
        lock(&self.inbox).messages.drain(..).collect()
    }

    /// What the link counted so far (receiving and sending).
    pub fn stats(&self) -> LinkStats {
        lock(&self.stats).clone()
    }
}

/// A robot's end of the team link (see the module doc).
pub struct TeamLink {
    robot: RobotId,
    team_key: String,
    session: zenoh::Session,
    intake: Arc<Intake>,
    alive: Arc<Mutex<BTreeSet<RobotId>>>,
    outbox: Option<SyncSender<Outgoing>>,
    sender: Option<JoinHandle<()>>,
    opened: std::time::Instant,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    _alive_subscriber: zenoh::pubsub::Subscriber<()>,
    _token: zenoh::liveliness::LivelinessToken,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic while holding one of these locks leaves plain counters and queues behind, still
    // consistent enough to use.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl TeamLink {
    /// Opens the link: a Zenoh peer session with the config's endpoints, this robot's
    /// liveliness token, and the subscriptions to its messages and to the team's liveliness.
    pub fn open(config: &LinkConfig) -> Result<TeamLink, LinkError> {
        let team_key = key_chunk(&config.team);
        let me = key_chunk(config.robot.as_str());
        let zconfig = zenoh_config(config, &team_key)?;
        let session = zenoh::open(zconfig).wait().map_err(zenoh_err)?;

        let intake = Arc::new(Intake::new(config));
        let subscriber = {
            let intake = intake.clone();
            session
                .declare_subscriber(format!("spomp/{team_key}/team/{me}/*/*"))
                .callback(move |sample| {
                    // Measured before it is copied: a 100 MB payload is refused without a copy.
                    let payload = sample.payload();
                    intake.offer(sample.key_expr().as_str(), payload.len(), || payload.to_bytes().into_owned());
                })
                .wait()
                .map_err(zenoh_err)?
        };
        let alive = Arc::new(Mutex::new(BTreeSet::new()));
        let alive_subscriber = {
            let (alive, roster) = (alive.clone(), intake.roster.clone());
            session
                .liveliness()
                .declare_subscriber(format!("spomp/{team_key}/alive/*"))
                .history(true)
                .callback(move |sample| {
                    let chunk = sample.key_expr().as_str().rsplit('/').next().unwrap_or("");
                    // Tokens of non-members are not tracked (anyone with the transport
                    // password can declare any number of them).
                    let Some(robot) = roster.admit(chunk) else { return };
                    let mut alive = lock(&alive);
                    match sample.kind() {
                        SampleKind::Put if roster.listed() || alive.len() < MAX_UNLISTED_SENDERS => {
                            alive.insert(robot);
                        }
                        SampleKind::Put => {}
                        SampleKind::Delete => {
                            alive.remove(&robot);
                        }
                    }
                })
                .wait()
                .map_err(zenoh_err)?
        };
        let token =
            session.liveliness().declare_token(format!("spomp/{team_key}/alive/{me}")).wait().map_err(zenoh_err)?;

        let (outbox, queue) = sync_channel::<Outgoing>(config.queue_messages.max(1));
        let sender = {
            let (session, intake) = (session.clone(), intake.clone());
            std::thread::Builder::new()
                .name(format!("team-link-{me}"))
                .spawn(move || send_loop(&session, &queue, &intake.stats))
                .map_err(|e| LinkError::Config(format!("starting the sender thread: {e}")))?
        };
        Ok(TeamLink {
            robot: config.robot.clone(),
            team_key,
            session,
            intake,
            alive,
            outbox: Some(outbox),
            sender: Some(sender),
            opened: std::time::Instant::now(),
            _subscriber: subscriber,
            _alive_subscriber: alive_subscriber,
            _token: token,
        })
    }

    /// This robot.
    pub fn robot(&self) -> &RobotId {
        &self.robot
    }

    /// Queues a sync message for `to` at `tier`'s priority; false if the queue was full and the
    /// message was dropped (counted). Never blocks.
    pub fn send(&self, to: &RobotId, tier: Tier, bytes: Vec<u8>) -> bool {
        let peer = key_chunk(to.as_str());
        let key = format!("spomp/{}/team/{peer}/{}/{}", self.team_key, key_chunk(self.robot.as_str()), tier_name(tier));
        let Some(outbox) = &self.outbox else { return false };
        match outbox.try_send(Outgoing { key, peer: to.to_string(), tier, bytes }) {
            Ok(()) => true,
            Err(TrySendError::Full(m) | TrySendError::Disconnected(m)) => {
                lock(&self.intake.stats).sent.entry(m.peer).or_default().entry(tier_name(tier)).or_default().dropped +=
                    1;
                false
            }
        }
    }

    /// The messages received since the last call, oldest first, with the sender each key
    /// expression named (which the receiver's signature check must confirm).
    pub fn receive(&self) -> Vec<(RobotId, Vec<u8>)> {
        self.intake.take()
    }

    /// The robots whose liveliness token is visible now (this one included once its own
    /// token is seen).
    pub fn reachable(&self) -> BTreeSet<RobotId> {
        lock(&self.alive).clone()
    }

    /// What crossed the link so far, with rates over the time since it opened.
    pub fn stats(&self) -> LinkStats {
        let mut stats = self.intake.stats();
        stats.elapsed_s = self.opened.elapsed().as_secs_f64();
        let rate = |c: &mut TierCounts| c.bytes_per_s = c.bytes as f64 / stats.elapsed_s.max(1e-9);
        stats.sent.values_mut().flat_map(|tiers| tiers.values_mut()).for_each(rate);
        stats.received.values_mut().for_each(rate);
        stats
    }

    /// Closes the session (peers see this robot's token go); waits for queued sends.
    pub fn close(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        self.outbox = None;
        if let Some(sender) = self.sender.take() {
            let _ = sender.join();
        }
        let _ = self.session.close().wait();
    }
}

impl Drop for TeamLink {
    fn drop(&mut self) {
        self.shutdown();
    }
}

fn send_loop(session: &zenoh::Session, queue: &Receiver<Outgoing>, stats: &Mutex<LinkStats>) {
    let mut publishers: HashMap<String, zenoh::pubsub::Publisher<'static>> = HashMap::new();
    while let Ok(msg) = queue.recv() {
        if !publishers.contains_key(&msg.key) {
            // The tier's priority and congestion control come from the session's QoS rules.
            match session.declare_publisher(msg.key.clone()).wait() {
                Ok(p) => {
                    publishers.insert(msg.key.clone(), p);
                }
                Err(_) => continue,
            }
        }
        let Some(publisher) = publishers.get(&msg.key) else { continue };
        let len = msg.bytes.len() as u64;
        let sent = publisher.put(msg.bytes).wait().is_ok();
        let mut stats = lock(stats);
        let counts = stats.sent.entry(msg.peer).or_default().entry(tier_name(msg.tier)).or_default();
        if sent {
            counts.messages += 1;
            counts.bytes += len;
        } else {
            counts.dropped += 1;
        }
    }
}

fn json_list(items: &[String]) -> Result<String, LinkError> {
    serde_json::to_string(items).map_err(|e| LinkError::Config(e.to_string()))
}

/// The Zenoh configuration of a robot's session.
fn zenoh_config(config: &LinkConfig, team_key: &str) -> Result<zenoh::Config, LinkError> {
    let mut z = zenoh::Config::default();
    let mut set = |key: &str, value: String| {
        z.insert_json5(key, &value).map_err(|e| LinkError::Config(format!("{key} = {value}: {e}")))
    };
    set("mode", "\"peer\"".into())?;
    for endpoint in config.listen.iter().chain(&config.connect) {
        if !endpoint.starts_with("tcp/") {
            return Err(LinkError::Config(format!("endpoint `{endpoint}`: only tcp/HOST:PORT endpoints are built in")));
        }
    }
    set("listen/endpoints", json_list(&config.listen)?)?;
    set("connect/endpoints", json_list(&config.connect)?)?;
    set("scouting/multicast/enabled", config.multicast_scouting.to_string())?;
    // Gossip tells peers of peers, so a robot reaches teammates its config does not name.
    set("scouting/gossip/enabled", "true".into())?;
    // Coordination first, maps last; a congested link drops rather than blocks (the sync
    // protocol resends what was not acknowledged).
    let qos = format!(
        r#"[
            {{ key_exprs: ["spomp/{t}/team/*/*/coordination"], config: {{ priority: "interactive_high", congestion_control: "drop", express: true }} }},
            {{ key_exprs: ["spomp/{t}/team/*/*/scans"], config: {{ priority: "data", congestion_control: "drop" }} }},
            {{ key_exprs: ["spomp/{t}/team/*/*/maps"], config: {{ priority: "background", congestion_control: "drop" }} }}
        ]"#,
        t = team_key
    );
    set("qos/publication", qos)?;
    if let Some(c) = &config.credentials {
        let user = serde_json::to_string(&c.user).map_err(|e| LinkError::Config(e.to_string()))?;
        let password = serde_json::to_string(&c.password).map_err(|e| LinkError::Config(e.to_string()))?;
        let dict = serde_json::to_string(&c.dictionary_file.display().to_string())
            .map_err(|e| LinkError::Config(e.to_string()))?;
        set("transport/auth/usrpwd/user", user)?;
        set("transport/auth/usrpwd/password", password)?;
        set("transport/auth/usrpwd/dictionary_file", dict)?;
    }
    Ok(z)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(members: Option<&[&str]>) -> LinkConfig {
        let mut config = LinkConfig::new("city", RobotId::new("base"));
        config.members = members.map(|m| m.iter().map(|r| RobotId::new(r)).collect());
        config.max_message_bytes = 1000;
        config.queue_messages = 8;
        config
    }

    fn key(from: &str) -> String {
        format!("spomp/city/team/base/{from}/coordination")
    }

    /// Regression (issue 36): every invented sender name got an entry of its own in the link's
    /// figures, kept for ever.
    #[test]
    fn invented_senders_are_refused_and_counted_without_an_entry_or_a_copy() {
        let intake = Intake::new(&config(Some(&["base", "ugv1"])));
        for k in 0..10_000 {
            intake.offer(&key(&format!("intruder-{k}")), 10, || panic!("a refused payload was copied"));
        }
        intake.offer(&key("ugv1"), 1001, || panic!("an oversized payload was copied"));
        for _ in 0..10 {
            intake.offer(&key("ugv1"), 3, || vec![1, 2, 3]);
        }
        let stats = intake.stats();
        assert_eq!(stats.refused, Refusals { unknown_sender: 10_000, oversized: 1, inbox_full: 2 });
        assert_eq!(stats.received.keys().collect::<Vec<_>>(), ["ugv1"]);
        assert_eq!(stats.received["ugv1"].messages, 8);
        let taken = intake.take();
        assert_eq!(taken.len(), 8, "the inbox holds queue_messages at most");
        assert!(taken.iter().all(|(from, bytes)| from.as_str() == "ugv1" && bytes == &[1, 2, 3]));
        assert!(intake.take().is_empty());
    }

    #[test]
    fn without_a_member_list_the_figures_name_a_bounded_number_of_senders() {
        let intake = Intake::new(&config(None));
        for k in 0..1000 {
            intake.offer(&key(&format!("s{k}")), 1, || vec![0]);
            intake.take();
        }
        let stats = intake.stats();
        assert_eq!(stats.received.len(), MAX_UNLISTED_SENDERS);
        assert_eq!(stats.received_unlisted.messages, 1000 - MAX_UNLISTED_SENDERS as u64);
    }
}
