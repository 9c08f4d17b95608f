//! The server's front door: it takes viewers that offer only the protocol's original name,
//! `foxglove.websocket.v1`, as well as those that offer `foxglove.sdk.v1`.
//!
//! The `foxglove` crate's server negotiates only the `foxglove.sdk.*` names and answers any other
//! offer with HTTP 400, which shuts out viewers from before the rename (Lichtblick before 1.22.1,
//! `@foxglove/ws-protocol` clients, foxglove_bridge-era tools). The two names are one protocol on
//! the wire, so the front listens where the user asked, and for each connection reads the
//! upgrade request, puts `foxglove.sdk.v1` for a lone `foxglove.websocket.v1` offer, hands the
//! request to the crate's server on a loopback port, puts the name the viewer offered back in
//! the answer, and from then on copies bytes both ways. Offers that name a `foxglove.sdk.*`
//! version pass unchanged.

use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use crate::{LEGACY_SUBPROTOCOL, SUBPROTOCOL};

/// The longest upgrade request or answer head taken, bytes (browsers send a few hundred).
const MAX_HEAD_BYTES: usize = 64 * 1024;
/// How often the accepting thread looks for a stop.
const ACCEPT_POLL: Duration = Duration::from_millis(20);
/// A viewer that sends no complete request head within this is dropped.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// The front: listening, and the connections it carries.
pub(crate) struct Front {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    accept: Option<JoinHandle<()>>,
    /// Both ends of every connection, to close at the stop.
    streams: Arc<Mutex<Vec<TcpStream>>>,
}

impl Front {
    /// Listens on `addr` and carries each connection to the server at `backend`.
    pub(crate) fn start(addr: SocketAddr, backend: SocketAddr) -> io::Result<Front> {
        let listener = TcpListener::bind(addr)?;
        listener.set_nonblocking(true)?;
        let bound = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let streams: Arc<Mutex<Vec<TcpStream>>> = Arc::default();
        let accept = {
            let (stop, streams) = (stop.clone(), streams.clone());
            std::thread::Builder::new().name("live-front".into()).spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    match listener.accept() {
                        Ok((viewer, _)) => {
                            let streams = streams.clone();
                            // A connection that fails is the viewer's loss only.
                            let _ = std::thread::Builder::new()
                                .name("live-front-conn".into())
                                .spawn(move || drop(carry(viewer, backend, &streams)));
                        }
                        Err(_) => std::thread::sleep(ACCEPT_POLL),
                    }
                }
            })?
        };
        Ok(Front { addr: bound, stop, accept: Some(accept), streams })
    }

    /// Where it listens.
    pub(crate) fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops taking viewers and closes every connection.
    pub(crate) fn stop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.accept.take() {
            let _ = t.join();
        }
        for s in self.streams.lock().unwrap_or_else(PoisonError::into_inner).drain(..) {
            let _ = s.shutdown(Shutdown::Both);
        }
    }
}

impl Drop for Front {
    fn drop(&mut self) {
        self.stop();
    }
}

/// One viewer's connection: the handshake with the names mapped, then bytes both ways.
fn carry(mut viewer: TcpStream, backend: SocketAddr, streams: &Mutex<Vec<TcpStream>>) -> io::Result<()> {
    viewer.set_nonblocking(false)?;
    viewer.set_nodelay(true)?;
    viewer.set_read_timeout(Some(HANDSHAKE_TIMEOUT))?;
    let (request, early) = read_head(&mut viewer)?;
    let (request, legacy) = map_request(&request);
    let mut server = TcpStream::connect(backend)?;
    server.set_nodelay(true)?;
    {
        let mut open = streams.lock().unwrap_or_else(PoisonError::into_inner);
        open.retain(|s| s.peer_addr().is_ok());
        open.push(viewer.try_clone()?);
        open.push(server.try_clone()?);
    }
    server.write_all(request.as_bytes())?;
    server.write_all(&early)?;
    let (answer, rest) = read_head(&mut server)?;
    let answer = if legacy { map_answer(&answer) } else { answer };
    viewer.write_all(answer.as_bytes())?;
    viewer.write_all(&rest)?;
    viewer.set_read_timeout(None)?;
    let (mut from_viewer, mut to_server) = (viewer.try_clone()?, server.try_clone()?);
    let upstream = std::thread::Builder::new().name("live-front-up".into()).spawn(move || {
        let _ = io::copy(&mut from_viewer, &mut to_server);
        let _ = to_server.shutdown(Shutdown::Write);
    })?;
    let _ = io::copy(&mut server, &mut viewer);
    let _ = viewer.shutdown(Shutdown::Both);
    let _ = server.shutdown(Shutdown::Both);
    let _ = upstream.join();
    Ok(())
}

/// Reads an HTTP head (through the blank line): the head as text and any bytes read past it.
fn read_head(stream: &mut TcpStream) -> io::Result<(String, Vec<u8>)> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            let head = String::from_utf8(buf).map_err(|_| io::Error::other("an HTTP head that is not UTF-8"))?;
            return Ok((head, rest));
        }
        if buf.len() > MAX_HEAD_BYTES {
            return Err(io::Error::other("an HTTP head longer than 64 KiB"));
        }
        let n = stream.read(&mut chunk)?;
        if n == 0 {
            return Err(io::ErrorKind::UnexpectedEof.into());
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

fn is_protocol_header(line: &str) -> bool {
    line.split_once(':').is_some_and(|(name, _)| name.trim().eq_ignore_ascii_case("sec-websocket-protocol"))
}

/// The upgrade request as the server takes it, and whether the viewer offered only the old
/// name (then the answer must name it).
fn map_request(head: &str) -> (String, bool) {
    let offered: Vec<&str> = head
        .split("\r\n")
        .filter(|l| is_protocol_header(l))
        .filter_map(|l| l.split_once(':').map(|(_, v)| v))
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .collect();
    let current = offered.iter().any(|p| p.starts_with("foxglove.sdk."));
    if current || !offered.contains(&LEGACY_SUBPROTOCOL) {
        return (head.to_string(), false);
    }
    let mut lines: Vec<String> = head.split("\r\n").filter(|l| !is_protocol_header(l)).map(String::from).collect();
    // The head ends with two empty strings (the blank line); the header goes before them.
    let at = lines.len().saturating_sub(2).max(1);
    lines.insert(at, format!("Sec-WebSocket-Protocol: {SUBPROTOCOL}"));
    (lines.join("\r\n"), true)
}

/// The server's answer with the old name in place of the one it chose.
fn map_answer(head: &str) -> String {
    head.split("\r\n")
        .map(|l| if is_protocol_header(l) { format!("Sec-WebSocket-Protocol: {LEGACY_SUBPROTOCOL}") } else { l.into() })
        .collect::<Vec<_>>()
        .join("\r\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    const REQUEST: &str = "GET / HTTP/1.1\r\nHost: x\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n";

    #[test]
    fn a_lone_old_name_is_offered_as_the_new_one_and_answered_as_the_old() {
        let (mapped, legacy) = map_request(REQUEST);
        assert!(legacy);
        assert_eq!(mapped, "GET / HTTP/1.1\r\nHost: x\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n");
        let answer = "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\n\r\n";
        assert_eq!(
            map_answer(answer),
            "HTTP/1.1 101 Switching Protocols\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n"
        );
    }

    #[test]
    fn offers_naming_a_current_version_or_neither_pass_unchanged() {
        for head in [
            "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: foxglove.sdk.v1, foxglove.websocket.v1\r\n\r\n",
            "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: other\r\n\r\n",
            "GET / HTTP/1.1\r\nHost: x\r\n\r\n",
        ] {
            assert_eq!(map_request(head), (head.to_string(), false));
        }
    }
}
