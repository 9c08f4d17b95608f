//! Sync latency over the team link on loopback: ugv1 claims a goal, and the time until ugv2's
//! team state shows the claim is measured, with signed messages and transport authentication as
//! `spomp run --keys` uses them. Each robot sends as soon as it has news (what a send round
//! costs on top); `spomp run` sends once per `team_period_s` (1 s), which adds up to that much.
//!
//! `cargo run --release -p spomp-zenoh --example sync_latency -- [CLAIMS]`

use std::net::TcpListener;
use std::sync::Arc;
use std::time::{Duration, Instant};

use spomp_core::{Point2, RobotId, Time};
use spomp_robot::RoundShape;
use spomp_robot::team_round::{round, single_tier};
use spomp_teamstate::{GoalOrigin, TeamState, TeamStateParams, TierSet};
use spomp_zenoh::{KeyDir, LinkConfig, TeamLink};

fn port() -> Result<u16, Box<dyn std::error::Error>> {
    Ok(TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let claims: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(200);
    let dir = std::env::temp_dir().join(format!("spomp-sync-latency-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let ids = [RobotId::new("ugv1"), RobotId::new("ugv2")];
    let keys = KeyDir::generate(&dir, "latency", &ids)?;
    let ports = [port()?, port()?];
    let mut robots = Vec::new();
    for (k, id) in ids.iter().enumerate() {
        let mut state = TeamState::new(id.clone(), k as u32 + 1, TeamStateParams::default())?;
        state.set_security(Arc::new(keys.security(id)?))?;
        let mut config = LinkConfig::new("latency", id.clone());
        config.listen = vec![format!("tcp/127.0.0.1:{}", ports[k])];
        if k == 1 {
            config.connect = vec![format!("tcp/127.0.0.1:{}", ports[0])];
        }
        config.credentials = Some(keys.credentials(id)?);
        robots.push((state, TeamLink::open(&config)?));
    }
    // Wait until each sees the other's liveliness token.
    let start = Instant::now();
    while !(robots[0].1.reachable().contains(&ids[1]) && robots[1].1.reachable().contains(&ids[0])) {
        if start.elapsed() > Duration::from_secs(10) {
            return Err("the robots never met".into());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut latencies = Vec::with_capacity(claims);
    for k in 0..claims {
        let now = Time::from_secs_f64(k as f64);
        let goal = robots[0].0.identify_goal(Point2::new(100.0 * k as f64, 0.0), GoalOrigin::Detected, now)?;
        let goal = goal.id().clone();
        let t0 = Instant::now();
        robots[0].0.claim(&goal, now)?;
        loop {
            for i in 0..2 {
                let peer = ids[1 - i].clone();
                let (state, link) = &mut robots[i];
                for (from, bytes) in link.receive() {
                    state.apply_bytes(&from, &bytes)?;
                }
                if link.reachable().contains(&peer) {
                    let sent = round(RoundShape::PerTier, TierSet::ALL, 1 << 20, |tiers, budget| {
                        state.make_sync(&peer, tiers, budget).map(|m| m.encode())
                    });
                    for (tiers, bytes) in sent {
                        if let Some(tier) = single_tier(tiers) {
                            link.send(&peer, tier, bytes);
                        }
                    }
                }
            }
            if robots[1].0.goal(&goal).is_some_and(|v| v.is_held_by(&ids[0])) {
                latencies.push(t0.elapsed());
                break;
            }
            if t0.elapsed() > Duration::from_secs(5) {
                return Err(format!("claim {k} never arrived").into());
            }
            std::thread::sleep(Duration::from_micros(200));
        }
    }
    latencies.sort();
    let q = |p: f64| latencies[((latencies.len() - 1) as f64 * p).round() as usize].as_secs_f64() * 1e3;
    println!(
        "claim on ugv1 → visible at ugv2 (signed, authenticated, loopback), {claims} claims: median {:.2} ms, p90 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        q(0.5),
        q(0.9),
        q(0.99),
        q(1.0)
    );
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
