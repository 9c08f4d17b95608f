//! The live view's side of a command: the recorder's messages served over the Foxglove
//! WebSocket protocol (`spomp sim --live`, `spomp run --live`; docs/live.md).

use std::io::{Seek, SeekFrom, Write};

use spomp_mcap::{MessageTap, MessageType};

/// Where the log goes when only the live view wants the messages (`--live --no-mcap`): nowhere,
/// keeping count of the position as a file would.
#[derive(Default)]
pub(crate) struct Discard {
    position: u64,
}

impl Write for Discard {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.position += buf.len() as u64;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Seek for Discard {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        let target = match pos {
            SeekFrom::Start(p) => Some(p),
            // Nothing is kept, so the end is where the writing got to.
            SeekFrom::Current(d) | SeekFrom::End(d) => self.position.checked_add_signed(d),
        };
        self.position = target.ok_or_else(|| std::io::Error::other("seek before the start"))?;
        Ok(self.position)
    }
}

/// The live view's side of the recorder: every message it writes, served as it is.
#[cfg(feature = "deploy")]
pub(crate) struct LiveTap {
    server: spomp_live::LiveServer,
    /// A message could not be served (reported once; the run goes on).
    failed: bool,
}

#[cfg(feature = "deploy")]
impl LiveTap {
    /// Serves through `server`.
    pub(crate) fn new(server: spomp_live::LiveServer) -> Self {
        LiveTap { server, failed: false }
    }

    /// Starts serving on `addr` under `name` (what a viewer shows for the connection).
    pub(crate) fn start(addr: std::net::SocketAddr, name: &str) -> anyhow::Result<Self> {
        Ok(Self::new(spomp_live::LiveServer::start(addr, name)?))
    }

    /// The address a viewer opens.
    pub(crate) fn url(&self) -> String {
        self.server.url()
    }
}

#[cfg(feature = "deploy")]
impl MessageTap for LiveTap {
    fn message(&mut self, topic: &str, message_type: &MessageType, log_time_ns: u64, cdr: &[u8], latched: bool) {
        let served = self.server.publish(topic, message_type.name, message_type.definition, log_time_ns, cdr, latched);
        if let Err(e) = served
            && !std::mem::replace(&mut self.failed, true)
        {
            errln!("live view: {e} (the run goes on; later failures are not reported)");
        }
    }
}

/// A build without the `deploy` feature has no live view: no tap can exist, and starting one
/// says how to get it.
#[cfg(not(feature = "deploy"))]
pub(crate) enum LiveTap {}

#[cfg(not(feature = "deploy"))]
impl LiveTap {
    /// The note that this build has no live view.
    pub(crate) fn start(_addr: std::net::SocketAddr, _name: &str) -> anyhow::Result<Self> {
        Err(crate::deploy::not_built_error("--live"))
    }

    /// Never called: no tap exists.
    pub(crate) fn url(&self) -> String {
        match *self {}
    }
}

#[cfg(not(feature = "deploy"))]
impl MessageTap for LiveTap {
    fn message(&mut self, _topic: &str, _type: &MessageType, _log_time_ns: u64, _cdr: &[u8], _latched: bool) {
        match *self {}
    }
}
