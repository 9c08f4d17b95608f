//! A spomp run, live, over the Foxglove WebSocket protocol. The `foxglove` crate negotiates it
//! under its current name, subprotocol `foxglove.sdk.v1` — on the wire the same protocol as
//! `foxglove.websocket.v1` (serverInfo, advertise, subscribe, binary message data). Viewers
//! from before the rename offer only the old name, which the crate refuses; a front of this
//! crate's own takes them too (`front`), so every current viewer connects.
//!
//! [`LiveServer`] serves ROS 2 channels: each message arrives as its topic, its ROS 2 type and
//! `ros2msg` definition, its log time and its CDR bytes — the way spomp's MCAP recorder writes
//! it (the CLI hands the recorder's messages over; this crate defines no channel of its own).
//! A channel is advertised to viewers when its first message is published. Messages of latched
//! channels (state that holds until the next message: the map, the goals) are kept, and a viewer
//! subscribing later is sent the latest one at once. The server advertises the `time`
//! capability and broadcasts the run's (simulated) time, so a viewer's clock follows the run.
//!
//! Opt-in ([`LiveOptions::points`]), the server also offers the protocol's `clientPublish`
//! capability and takes points a viewer publishes (Foxglove's 3-D panel "Publish point",
//! `geometry_msgs/PointStamped`, json or cdr; see [`points`]): each is handed to the caller's
//! handler, which decides what it means (the CLI: an operator's "add goal"). Without it a
//! viewer's advertisement is refused, as before.
//!
//! Only subscribed channels cost anything: a message nobody subscribes to is dropped before it
//! is copied. Each viewer has a bounded queue (1024 messages by default); a slow viewer loses
//! the oldest messages, and never slows the run down.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, PoisonError};

mod front;
pub mod points;
#[cfg(test)]
mod tests;
#[cfg(any(test, feature = "viewer"))]
pub mod viewer;

use foxglove::websocket::{Capability, ChannelView, Client, ClientChannel, ServerListener, Status};

use foxglove::{ChannelBuilder, Context, PartialMetadata, RawChannel, Schema, WebSocketServer, WebSocketServerHandle};
pub use points::{PointHandler, PublishedPoint};

/// Where the live view listens unless told otherwise: loopback only.
pub const DEFAULT_ADDR: SocketAddr = SocketAddr::new(std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST), 8765);

/// The WebSocket subprotocol the server accepts (see the crate documentation).
pub const SUBPROTOCOL: &str = "foxglove.sdk.v1";

/// The protocol's original name: viewers from before the rename offer only it, and the server
/// takes it (answering with it) as well as [`SUBPROTOCOL`].
pub const LEGACY_SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// Schema encoding of every channel: ROS 2 message definitions.
pub const SCHEMA_ENCODING: &str = "ros2msg";

/// Message encoding of every channel: CDR with the ROS 2 encapsulation header.
pub const MESSAGE_ENCODING: &str = "cdr";

/// How often, in log time, the server tells viewers the run's time, nanoseconds.
const TIME_BROADCAST_PERIOD_NS: u64 = 100_000_000;

/// Why the live view failed.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The server could not start (the address is in use, not local, …).
    #[error("starting the Foxglove WebSocket server on {addr}: {message}")]
    Start {
        /// Where it was to listen.
        addr: SocketAddr,
        /// What went wrong.
        message: String,
    },
    /// A channel could not be created.
    #[error("creating the live channel {topic}: {message}")]
    Channel {
        /// Its topic.
        topic: String,
        /// What went wrong.
        message: String,
    },
}

/// The latest message of a latched channel.
struct Latest {
    log_time_ns: u64,
    data: Vec<u8>,
}

/// Latest messages of the latched channels, by topic; shared with the server's listener.
type LatchedMessages = Arc<Mutex<HashMap<String, Latest>>>;

/// What the server does for its viewers beyond serving channels: sends a new subscriber of a
/// latched channel its latest message, and hands published points to the handler.
struct LatchedReplay {
    context: Arc<Context>,
    latched: LatchedMessages,
    points: Option<PointHandler>,
}

impl ServerListener for LatchedReplay {
    fn on_client_advertise(&self, client: Client, channel: &ClientChannel) {
        if self.points.is_none() {
            return;
        }
        match points::accepts(&channel.schema_name, &channel.encoding) {
            Ok(()) => client.send_status(Status::info(format!(
                "{}: each point published here becomes an operator's goal",
                channel.topic
            ))),
            Err(why) => client.send_status(Status::warning(format!("{}: {why}", channel.topic))),
        }
    }

    fn on_message_data(&self, client: Client, channel: &ClientChannel, payload: &[u8]) {
        let Some(handler) = &self.points else { return };
        let answer = points::accepts(&channel.schema_name, &channel.encoding)
            .and_then(|()| points::decode(&channel.topic, &channel.encoding, payload))
            .and_then(|point| handler(&point));
        client.send_status(match answer {
            Ok(done) => Status::info(format!("{}: {done}", channel.topic)),
            Err(why) => Status::error(format!("{}: refused: {why}", channel.topic)),
        });
    }

    fn on_subscribe(&self, client: Client, channel: ChannelView<'_>) {
        // Copied out so the lock is not held while the message is queued.
        let latest = {
            let latched = self.latched.lock().unwrap_or_else(PoisonError::into_inner);
            latched.get(channel.topic()).map(|l| (l.log_time_ns, l.data.clone()))
        };
        let (Some((log_time_ns, data)), Some(raw)) = (latest, self.context.get_channel_by_topic(channel.topic()))
        else {
            return;
        };
        raw.log_with_meta_to_sink(&data, PartialMetadata::with_log_time(log_time_ns), client.sink_id());
    }
}

/// How the server serves, beyond its address and name.
#[derive(Clone, Default)]
pub struct LiveOptions {
    /// Take points viewers publish (the `clientPublish` capability, encodings `json` and
    /// `cdr`) and hand each to this handler. None: viewers may only watch.
    pub points: Option<PointHandler>,
}

impl std::fmt::Debug for LiveOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveOptions").field("points", &self.points.is_some()).finish()
    }
}

/// A running live view: a Foxglove WebSocket server and the channels published on it.
pub struct LiveServer {
    context: Arc<Context>,
    handle: Option<WebSocketServerHandle>,
    /// Where viewers connect; it hands them to the crate's server (see `front`).
    front: Option<front::Front>,
    addr: SocketAddr,
    channels: HashMap<String, Arc<RawChannel>>,
    latched: LatchedMessages,
    /// Log time last broadcast as the run's time.
    time_sent_ns: Option<u64>,
}

impl LiveServer {
    /// Starts serving on `addr` (port 0: any free port; see [`LiveServer::local_addr`]).
    /// `name` is what viewers show as the server's name.
    pub fn start(addr: SocketAddr, name: &str) -> Result<Self, LiveError> {
        LiveServer::start_with(addr, name, LiveOptions::default())
    }

    /// [`LiveServer::start`] with `options` (points published by viewers, …).
    pub fn start_with(addr: SocketAddr, name: &str, options: LiveOptions) -> Result<Self, LiveError> {
        // A context of its own: channels and subscriptions of one server only (tests run
        // several at once in a process).
        let context = Context::new();
        let latched = LatchedMessages::default();
        let takes_points = options.points.is_some();
        let listener =
            Arc::new(LatchedReplay { context: context.clone(), latched: latched.clone(), points: options.points });
        let mut capabilities = vec![Capability::Time];
        if takes_points {
            capabilities.push(Capability::ClientPublish);
        }
        // The crate's server listens on loopback only, behind the front.
        let mut server = WebSocketServer::new()
            .context(&context)
            .name(name)
            .bind("127.0.0.1", 0)
            .capabilities(capabilities)
            .listener(listener);
        if takes_points {
            // Foxglove publishes in the first of these it can write: json whatever its profile.
            server = server.supported_encodings(points::POINT_ENCODINGS);
        }
        let handle = server.start_blocking().map_err(|e| LiveError::Start { addr, message: e.to_string() })?;
        let backend = SocketAddr::from(([127, 0, 0, 1], handle.port()));
        let front = match front::Front::start(addr, backend) {
            Ok(f) => f,
            Err(e) => {
                handle.stop().wait_blocking();
                return Err(LiveError::Start { addr, message: e.to_string() });
            }
        };
        let bound = front.local_addr();
        Ok(LiveServer {
            context,
            handle: Some(handle),
            front: Some(front),
            addr: bound,
            channels: HashMap::new(),
            latched,
            time_sent_ns: None,
        })
    }

    /// The address the server listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// What a viewer opens: `ws://HOST:PORT`.
    pub fn url(&self) -> String {
        format!("ws://{}", self.addr)
    }

    /// Viewers connected now.
    pub fn client_count(&self) -> usize {
        self.handle.as_ref().map_or(0, WebSocketServerHandle::client_count)
    }

    /// Publishes one message: `cdr` (with the encapsulation header) on `topic`, whose ROS 2 type
    /// is `type_name` with `definition`, at `log_time_ns`. The first message on a topic
    /// advertises its channel; a topic keeps the type of its first message. `latched`: the
    /// message stays the topic's state until the next one, and later subscribers get it.
    pub fn publish(
        &mut self,
        topic: &str,
        type_name: &str,
        definition: &'static str,
        log_time_ns: u64,
        cdr: &[u8],
        latched: bool,
    ) -> Result<(), LiveError> {
        let channel = match self.channels.get(topic) {
            Some(c) => c,
            None => {
                let channel = ChannelBuilder::new(topic)
                    .context(&self.context)
                    .schema(Schema::new(type_name, SCHEMA_ENCODING, definition.as_bytes()))
                    .message_encoding(MESSAGE_ENCODING)
                    .build_raw()
                    .map_err(|e| LiveError::Channel { topic: topic.to_string(), message: e.to_string() })?;
                self.channels.entry(topic.to_string()).or_insert(channel)
            }
        };
        if latched {
            let mut store = self.latched.lock().unwrap_or_else(PoisonError::into_inner);
            store.insert(topic.to_string(), Latest { log_time_ns, data: cdr.to_vec() });
        }
        channel.log_with_meta(cdr, PartialMetadata::with_log_time(log_time_ns));
        if self.time_sent_ns.is_none_or(|t| log_time_ns >= t.saturating_add(TIME_BROADCAST_PERIOD_NS))
            && let Some(h) = &self.handle
        {
            h.broadcast_time(log_time_ns);
            self.time_sent_ns = Some(log_time_ns);
        }
        Ok(())
    }

    /// Stops serving: viewers are disconnected; returns once the server's tasks have ended.
    pub fn stop(mut self) {
        self.shut_down();
    }

    fn shut_down(&mut self) {
        if let Some(mut front) = self.front.take() {
            front.stop();
        }
        if let Some(handle) = self.handle.take() {
            handle.stop().wait_blocking();
        }
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        self.shut_down();
    }
}
