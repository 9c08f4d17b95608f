//! A minimal, blocking viewer of the Foxglove WebSocket protocol, written from the protocol's
//! description rather than with the server's own code, so tests check what a real viewer
//! sees: the handshake (offering `foxglove.sdk.v1` and `foxglove.websocket.v1`, as the
//! Foxglove app does), the JSON `serverInfo` and `advertise`
//! messages, `subscribe`, and binary message data (opcode 1, subscription id, log time,
//! payload). Also counts the bytes it receives (the live view's bandwidth).

use std::collections::BTreeMap;
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use tungstenite::client::IntoClientRequest;
use tungstenite::http::HeaderValue;
use tungstenite::{Message, WebSocket};

use crate::{LEGACY_SUBPROTOCOL, SUBPROTOCOL};

/// Opcode of a binary message-data frame from the server.
const OP_MESSAGE_DATA: u8 = 0x01;
/// Opcode of a binary message-data frame from a client (on a channel it advertised).
const OP_CLIENT_MESSAGE_DATA: u8 = 0x01;
/// Opcode of a binary time frame from the server.
const OP_TIME: u8 = 0x02;
/// Most subscriptions sent again after a refusal (see [`Viewer::retry_refused_subscription`]).
const MAX_SUBSCRIBE_RETRIES: u32 = 100;

/// Why the viewer failed.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// Connecting or the WebSocket failed.
    #[error("websocket: {0}")]
    WebSocket(#[from] Box<tungstenite::Error>),
    /// The TCP connection failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// The server broke the protocol.
    #[error("protocol: {0}")]
    Protocol(String),
    /// What was waited for did not come in time.
    #[error("timed out waiting for {0}")]
    Timeout(String),
}

impl From<tungstenite::Error> for ViewerError {
    fn from(e: tungstenite::Error) -> Self {
        ViewerError::WebSocket(Box::new(e))
    }
}

/// A channel as the server advertised it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AdvertisedChannel {
    /// The server's channel id.
    pub id: u64,
    /// Topic.
    pub topic: String,
    /// Message encoding (`cdr`).
    pub encoding: String,
    /// Schema name (the ROS 2 type).
    pub schema_name: String,
    /// Schema encoding (`ros2msg`).
    pub schema_encoding: String,
    /// The schema (the ROS 2 definition).
    pub schema: String,
}

/// One message received on a subscription.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReceivedMessage {
    /// The topic it was subscribed as.
    pub topic: String,
    /// Log time, nanoseconds.
    pub log_time_ns: u64,
    /// The payload (CDR for spomp's channels).
    pub data: Vec<u8>,
}

/// A connected viewer.
pub struct Viewer {
    socket: WebSocket<TcpStream>,
    /// The server's `serverInfo` message.
    pub server_info: Value,
    /// Channels advertised so far, by topic.
    pub channels: BTreeMap<String, AdvertisedChannel>,
    /// Subscription id → topic.
    subscriptions: BTreeMap<u32, String>,
    /// The latest time the server broadcast, nanoseconds.
    pub server_time_ns: Option<u64>,
    /// Bytes of every frame received (payloads as sent on the wire, without framing).
    pub bytes_received: u64,
    /// The `status` messages the server sent (warnings and errors about this connection).
    pub statuses: Vec<String>,
    /// Subscriptions sent again after the server refused them.
    retries: u32,
}

impl Viewer {
    /// Connects to `addr` asking for the Foxglove subprotocol and reads the server's
    /// `serverInfo`. Reads block for at most `timeout`.
    pub fn connect(addr: SocketAddr, timeout: Duration) -> Result<Viewer, ViewerError> {
        Viewer::connect_offering(addr, &[SUBPROTOCOL, LEGACY_SUBPROTOCOL], timeout)
    }

    /// Connects offering the subprotocols `offered` (a viewer from before the protocol's rename
    /// offers only [`LEGACY_SUBPROTOCOL`]); the server must choose one of them.
    pub fn connect_offering(addr: SocketAddr, offered: &[&str], timeout: Duration) -> Result<Viewer, ViewerError> {
        let mut request = format!("ws://{addr}").into_client_request()?;
        let offered_list = offered.join(", ");
        let offered_header = HeaderValue::from_str(&offered_list).map_err(|e| ViewerError::Protocol(e.to_string()))?;
        request.headers_mut().insert("Sec-WebSocket-Protocol", offered_header);
        let stream = TcpStream::connect_timeout(&addr, timeout)?;
        stream.set_read_timeout(Some(timeout))?;
        let (socket, response) = tungstenite::client(request, stream).map_err(|e| match e {
            tungstenite::HandshakeError::Failure(e) => ViewerError::from(e),
            tungstenite::HandshakeError::Interrupted(_) => ViewerError::Timeout("the handshake".into()),
        })?;
        let protocol = response.headers().get("Sec-WebSocket-Protocol").and_then(|v| v.to_str().ok());
        if !protocol.is_some_and(|p| offered.contains(&p)) {
            return Err(ViewerError::Protocol(format!("the server chose subprotocol {protocol:?}")));
        }
        let mut viewer = Viewer {
            socket,
            server_info: Value::Null,
            channels: BTreeMap::new(),
            subscriptions: BTreeMap::new(),
            server_time_ns: None,
            bytes_received: 0,
            statuses: Vec::new(),
            retries: 0,
        };
        let deadline = Instant::now() + timeout;
        while viewer.server_info.is_null() {
            viewer.read_before(deadline, "serverInfo")?;
        }
        Ok(viewer)
    }

    /// Reads until every topic of `topics` is advertised, or `timeout` passes.
    pub fn wait_for_channels(&mut self, topics: &[&str], timeout: Duration) -> Result<(), ViewerError> {
        let deadline = Instant::now() + timeout;
        while let Some(missing) = topics.iter().find(|t| !self.channels.contains_key(**t)) {
            let what = format!("the advertisement of {missing}");
            self.read_before(deadline, &what)?;
        }
        Ok(())
    }

    /// Reads until the server has broadcast a time of at least `at_least_ns`, or `timeout`
    /// passes.
    pub fn wait_for_time(&mut self, at_least_ns: u64, timeout: Duration) -> Result<u64, ViewerError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(t) = self.server_time_ns.filter(|t| *t >= at_least_ns) {
                return Ok(t);
            }
            self.read_before(deadline, "the server's time")?;
        }
    }

    /// Subscribes to advertised topics; the subscription ids are 1, 2, … in the order given.
    pub fn subscribe(&mut self, topics: &[&str]) -> Result<(), ViewerError> {
        let mut subscriptions = Vec::new();
        for topic in topics {
            let channel = self
                .channels
                .get(*topic)
                .ok_or_else(|| ViewerError::Protocol(format!("{topic} was not advertised")))?;
            let id = self.subscriptions.len() as u32 + 1;
            self.subscriptions.insert(id, (*topic).to_string());
            subscriptions.push(json!({ "id": id, "channelId": channel.id }));
        }
        let text = json!({ "op": "subscribe", "subscriptions": subscriptions }).to_string();
        self.socket.send(Message::text(text))?;
        Ok(())
    }

    /// Advertises a client channel `id` on `topic` (the server must offer `clientPublish`):
    /// what Foxglove's 3-D panel sends before its first "Publish point".
    pub fn advertise(&mut self, id: u32, topic: &str, encoding: &str, schema_name: &str) -> Result<(), ViewerError> {
        let channel = json!({ "id": id, "topic": topic, "encoding": encoding, "schemaName": schema_name });
        let text = json!({ "op": "advertise", "channels": [channel] }).to_string();
        self.socket.send(Message::text(text))?;
        Ok(())
    }

    /// Publishes `payload` on the advertised client channel `id` (binary opcode 1, the channel
    /// id, the payload).
    pub fn publish(&mut self, id: u32, payload: &[u8]) -> Result<(), ViewerError> {
        let mut frame = Vec::with_capacity(5 + payload.len());
        frame.push(OP_CLIENT_MESSAGE_DATA);
        frame.extend_from_slice(&id.to_le_bytes());
        frame.extend_from_slice(payload);
        self.socket.send(Message::binary(frame))?;
        Ok(())
    }

    /// Reads until the server sends a status containing `needle` (the first such is returned),
    /// or `timeout` passes. Statuses received earlier count.
    pub fn wait_for_status(&mut self, needle: &str, timeout: Duration) -> Result<String, ViewerError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(s) = self.statuses.iter().find(|s| s.contains(needle)) {
                return Ok(s.clone());
            }
            self.read_before(deadline, &format!("a status saying `{needle}`"))?;
        }
    }

    /// Reads until a message on a subscription arrives, or `timeout` passes.
    pub fn next_message(&mut self, timeout: Duration) -> Result<ReceivedMessage, ViewerError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(m) = self.read_before(deadline, "a message")? {
                return Ok(m);
            }
        }
    }

    /// [`Viewer::read_one`], waiting no later than `deadline`; `what` names what was awaited.
    fn read_before(&mut self, deadline: Instant, what: &str) -> Result<Option<ReceivedMessage>, ViewerError> {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(ViewerError::Timeout(what.to_string()));
        }
        self.socket.get_ref().set_read_timeout(Some(left))?;
        match self.read_one() {
            Err(ViewerError::WebSocket(e))
                if matches!(&*e, tungstenite::Error::Io(io)
                    if matches!(io.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut)) =>
            {
                Err(ViewerError::Timeout(what.to_string()))
            }
            other => other,
        }
    }

    /// Reads one frame: a JSON message updates what the viewer knows; message data is returned.
    pub fn read_one(&mut self) -> Result<Option<ReceivedMessage>, ViewerError> {
        let frame = self.socket.read()?;
        match frame {
            Message::Text(text) => {
                self.bytes_received += text.len() as u64;
                let value: Value = serde_json::from_str(text.as_str())
                    .map_err(|e| ViewerError::Protocol(format!("a text frame is not JSON: {e}")))?;
                self.on_json(value)?;
                Ok(None)
            }
            Message::Binary(bytes) => {
                self.bytes_received += bytes.len() as u64;
                self.on_binary(&bytes)
            }
            Message::Close(_) => Err(ViewerError::Protocol("the server closed the connection".into())),
            _ => Ok(None),
        }
    }

    fn on_json(&mut self, value: Value) -> Result<(), ViewerError> {
        let text = |v: &Value, key: &str| v.get(key).and_then(Value::as_str).map(str::to_string);
        match value.get("op").and_then(Value::as_str) {
            Some("serverInfo") => self.server_info = value,
            Some("advertise") => {
                let channels = value
                    .get("channels")
                    .and_then(Value::as_array)
                    .ok_or_else(|| ViewerError::Protocol("advertise without channels".into()))?;
                for c in channels {
                    let field = |key: &str| {
                        text(c, key)
                            .ok_or_else(|| ViewerError::Protocol(format!("advertised channel lacks {key}: {c}")))
                    };
                    let id = c
                        .get("id")
                        .and_then(Value::as_u64)
                        .ok_or_else(|| ViewerError::Protocol(format!("advertised channel lacks id: {c}")))?;
                    let channel = AdvertisedChannel {
                        id,
                        topic: field("topic")?,
                        encoding: field("encoding")?,
                        schema_name: field("schemaName")?,
                        schema_encoding: text(c, "schemaEncoding").unwrap_or_default(),
                        schema: field("schema")?,
                    };
                    self.channels.insert(channel.topic.clone(), channel);
                }
            }
            Some("unadvertise") => {
                let ids: Vec<u64> = value
                    .get("channelIds")
                    .and_then(Value::as_array)
                    .map(|a| a.iter().filter_map(Value::as_u64).collect())
                    .unwrap_or_default();
                self.channels.retain(|_, c| !ids.contains(&c.id));
            }
            Some("status") => {
                let message = text(&value, "message").unwrap_or_default();
                self.retry_refused_subscription(&message)?;
                self.statuses.push(message);
            }
            _ => {} // removeStatus, …: nothing a viewer of data needs
        }
        Ok(())
    }

    /// The `foxglove` server (0.30) queues a channel's advertisement before it registers the
    /// channel for the connection, so a subscription sent the moment the advertisement arrives
    /// can be refused with "Unknown channel ID: N". The channel exists: subscribe again.
    fn retry_refused_subscription(&mut self, status: &str) -> Result<(), ViewerError> {
        let Some(channel_id) = status.strip_prefix("Unknown channel ID: ").and_then(|n| n.trim().parse::<u64>().ok())
        else {
            return Ok(());
        };
        let Some(topic) = self.channels.values().find(|c| c.id == channel_id).map(|c| c.topic.clone()) else {
            return Ok(());
        };
        let Some(&id) = self.subscriptions.iter().find(|(_, t)| **t == topic).map(|(id, _)| id) else {
            return Ok(());
        };
        if self.retries >= MAX_SUBSCRIBE_RETRIES {
            return Err(ViewerError::Protocol(format!("the server keeps refusing the subscription to {topic}")));
        }
        self.retries += 1;
        let text = json!({ "op": "subscribe", "subscriptions": [{ "id": id, "channelId": channel_id }] }).to_string();
        self.socket.send(Message::text(text))?;
        Ok(())
    }

    fn on_binary(&mut self, bytes: &[u8]) -> Result<Option<ReceivedMessage>, ViewerError> {
        let short = || ViewerError::Protocol(format!("a binary frame of {} bytes is too short", bytes.len()));
        let (&op, rest) = bytes.split_first().ok_or_else(short)?;
        match op {
            OP_MESSAGE_DATA => {
                let id = rest.get(0..4).ok_or_else(short)?;
                let time = rest.get(4..12).ok_or_else(short)?;
                let data = rest.get(12..).ok_or_else(short)?;
                let subscription = u32::from_le_bytes(id.try_into().map_err(|_| short())?);
                let log_time_ns = u64::from_le_bytes(time.try_into().map_err(|_| short())?);
                let topic =
                    self.subscriptions.get(&subscription).cloned().ok_or_else(|| {
                        ViewerError::Protocol(format!("data for unknown subscription {subscription}"))
                    })?;
                Ok(Some(ReceivedMessage { topic, log_time_ns, data: data.to_vec() }))
            }
            OP_TIME => {
                let time = rest.get(0..8).ok_or_else(short)?;
                self.server_time_ns = Some(u64::from_le_bytes(time.try_into().map_err(|_| short())?));
                Ok(None)
            }
            _ => Ok(None),
        }
    }
}
