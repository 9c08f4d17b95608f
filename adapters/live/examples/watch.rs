//! Watches a live view the way Foxglove does with every panel open: subscribes to every channel
//! as it is advertised and counts what arrives, per topic, until the server goes away. Prints
//! the bytes per second received (the live view's bandwidth to one viewer).
//!
//! `cargo run -p spomp-live --features viewer --example watch -- 127.0.0.1:8765`

use std::collections::{BTreeMap, BTreeSet};
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use spomp_live::viewer::{Viewer, ViewerError};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let addr: SocketAddr = std::env::args().nth(1).as_deref().unwrap_or("127.0.0.1:8765").parse()?;
    // The server may not be up yet: retry for a minute.
    let started = Instant::now();
    let mut viewer = loop {
        match Viewer::connect(addr, Duration::from_secs(30)) {
            Ok(v) => break v,
            Err(e) if started.elapsed() < Duration::from_secs(60) => {
                eprintln!("waiting for {addr}: {e}");
                std::thread::sleep(Duration::from_millis(200));
            }
            Err(e) => return Err(e.into()),
        }
    };
    let connected = Instant::now();
    let mut subscribed: BTreeSet<String> = BTreeSet::new();
    let mut per_topic: BTreeMap<String, (u64, u64)> = BTreeMap::new();
    loop {
        let fresh: Vec<String> = viewer.channels.keys().filter(|t| !subscribed.contains(*t)).cloned().collect();
        if !fresh.is_empty() {
            let topics: Vec<&str> = fresh.iter().map(String::as_str).collect();
            viewer.subscribe(&topics)?;
            subscribed.extend(fresh);
        }
        match viewer.read_one() {
            Ok(Some(m)) => {
                let entry = per_topic.entry(m.topic).or_default();
                entry.0 += 1;
                entry.1 += m.data.len() as u64;
            }
            Ok(None) => {}
            Err(ViewerError::Protocol(_) | ViewerError::WebSocket(_) | ViewerError::Io(_)) => break,
            Err(e) => return Err(e.into()),
        }
    }
    let seconds = connected.elapsed().as_secs_f64();
    for (topic, (n, bytes)) in &per_topic {
        println!("{n:8} msgs {bytes:12} B  {topic}");
    }
    println!(
        "{} channels, {} bytes in {seconds:.1} s wall: {:.0} B/s ({:.1} kB/s)",
        subscribed.len(),
        viewer.bytes_received,
        viewer.bytes_received as f64 / seconds,
        viewer.bytes_received as f64 / seconds / 1e3
    );
    Ok(())
}
