//! Robots' team states synced over real Zenoh sessions on loopback: convergence, transport
//! authentication, rogue senders, a partition that heals.
#![allow(clippy::unwrap_used)] // tests may unwrap

use std::net::TcpListener;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use spomp_core::{Point2, Pose2, RobotId, Time};
use spomp_robot::RoundShape;
use spomp_robot::team_round::{round, single_tier};
use spomp_teamstate::{GoalOrigin, TeamState, TeamStateParams, TierSet};
use spomp_zenoh::{Credentials, KeyDir, LinkConfig, TeamLink};

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn key_dir(name: &str, robots: &[&str]) -> (PathBuf, KeyDir) {
    let dir = std::env::temp_dir().join(format!("spomp-link-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let ids: Vec<RobotId> = robots.iter().map(|r| RobotId::new(r)).collect();
    let keys = KeyDir::generate(&dir, "city", &ids).unwrap();
    (dir, keys)
}

struct Member {
    state: TeamState,
    link: Option<TeamLink>,
    config: LinkConfig,
    rejected: usize,
}

impl Member {
    fn new(keys: &KeyDir, name: &str, priority: u32, port: u16, connect: &[u16]) -> Member {
        let id = RobotId::new(name);
        let mut state = TeamState::new(id.clone(), priority, TeamStateParams::default()).unwrap();
        state.set_security(Arc::new(keys.security(&id).unwrap())).unwrap();
        let mut config = LinkConfig::new("city", id.clone());
        config.listen = vec![format!("tcp/127.0.0.1:{port}")];
        config.connect = connect.iter().map(|p| format!("tcp/127.0.0.1:{p}")).collect();
        config.credentials = Some(keys.credentials(&id).unwrap());
        let link = Some(TeamLink::open(&config).unwrap());
        Member { state, link, config, rejected: 0 }
    }

    fn pump(&mut self, peers: &[RobotId], now: f64) {
        self.state.advance_clock(Time::from_secs_f64(now));
        let Some(link) = &self.link else { return };
        for (from, bytes) in link.receive() {
            if self.state.apply_bytes(&from, &bytes).is_err() {
                self.rejected += 1;
            }
        }
        // The robot layer's round: a message per tier, coordination first, within the budget.
        let reachable = link.reachable();
        for peer in peers.iter().filter(|p| reachable.contains(*p)) {
            let sent = round(RoundShape::PerTier, TierSet::ALL, 64 * 1024, |tiers, budget| {
                self.state.make_sync(peer, tiers, budget).map(|m| m.encode())
            });
            for (tiers, bytes) in sent {
                if let Some(tier) = single_tier(tiers) {
                    link.send(peer, tier, bytes);
                }
            }
        }
    }
}

/// Pumps every member every 20 ms until `done` or `limit`; returns the time it took.
fn run_until(members: &mut [Member], limit: Duration, mut done: impl FnMut(&[Member]) -> bool) -> Option<Duration> {
    let ids: Vec<RobotId> = members.iter().map(|m| m.state.self_id().clone()).collect();
    let start = Instant::now();
    while start.elapsed() < limit {
        for m in members.iter_mut() {
            let peers: Vec<RobotId> = ids.iter().filter(|p| *p != m.state.self_id()).cloned().collect();
            m.pump(&peers, start.elapsed().as_secs_f64() + 1.0);
        }
        if done(members) {
            return Some(start.elapsed());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    None
}

fn converged(members: &[Member]) -> bool {
    members.windows(2).all(|w| w[0].state.same_records(&w[1].state))
}

#[test]
fn three_robots_converge_and_a_partition_heals() {
    let (dir, keys) = key_dir("heal", &["ugv1", "ugv2", "base"]);
    let ports = [free_port(), free_port(), free_port()];
    let mut members = vec![
        Member::new(&keys, "ugv1", 1, ports[0], &[]),
        Member::new(&keys, "ugv2", 2, ports[1], &[ports[0]]),
        Member::new(&keys, "base", 9, ports[2], &[ports[0], ports[1]]),
    ];
    let g = members[0].state.identify_goal(Point2::new(40.0, 5.0), GoalOrigin::Detected, Time::ZERO).unwrap();
    members[0].state.claim(g.id(), Time::from_secs_f64(0.5)).unwrap();
    members[1].state.set_pose(Pose2::new(1.0, 2.0, 0.0), Time::from_secs_f64(0.5)).unwrap();
    let took = run_until(&mut members, Duration::from_secs(20), converged).expect("no convergence in 20 s");
    eprintln!("three robots converged in {took:?}");
    assert!(members[2].state.goal(g.id()).unwrap().is_held_by(&RobotId::new("ugv1")));

    // Partition: ugv2's session goes down; meanwhile ugv1 and the base learn more.
    let cut = members[1].link.take().unwrap();
    cut.close();
    members[0].state.identify_goal(Point2::new(-60.0, 5.0), GoalOrigin::Detected, Time::from_secs_f64(2.0)).unwrap();
    members[2].state.set_pose(Pose2::new(9.0, 9.0, 0.0), Time::from_secs_f64(2.0)).unwrap();
    run_until(&mut members, Duration::from_secs(3), |_| false);
    assert!(!members[1].state.same_records(&members[0].state), "ugv2 was cut off");
    // Heal: ugv2 comes back on the same endpoints.
    members[1].link = Some(TeamLink::open(&members[1].config).unwrap());
    let took = run_until(&mut members, Duration::from_secs(20), converged).expect("no convergence after healing");
    eprintln!("converged {took:?} after the partition healed");
    assert_eq!(members.iter().map(|m| m.rejected).sum::<usize>(), 0);
    let stats = members[0].link.as_ref().unwrap().stats();
    assert!(stats.sent["ugv2"]["coordination"].bytes > 0, "{stats:?}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn rogues_without_keys_change_nothing_and_are_counted() {
    let (dir, keys) = key_dir("rogue", &["ugv1", "ugv2"]);
    let ports = [free_port(), free_port(), free_port(), free_port()];
    let mut members =
        vec![Member::new(&keys, "ugv1", 1, ports[0], &[]), Member::new(&keys, "ugv2", 2, ports[1], &[ports[0]])];
    let g = members[0].state.identify_goal(Point2::new(40.0, 5.0), GoalOrigin::Detected, Time::ZERO).unwrap();
    run_until(&mut members, Duration::from_secs(20), converged).expect("no convergence");

    // Rogue 1: no transport password. Zenoh refuses its session, so nothing it sends arrives.
    let mut outsider_config = LinkConfig::new("city", RobotId::new("ugv1"));
    outsider_config.listen = vec![format!("tcp/127.0.0.1:{}", ports[2])];
    outsider_config.connect = vec![format!("tcp/127.0.0.1:{}", ports[0])];
    let outsider = TeamLink::open(&outsider_config).unwrap();
    // Rogue 2: it has the team's transport dictionary (an insider radio, a leaked password) but
    // not ugv1's signing key; it claims to be ugv1 and signs with a key of its own.
    let (rogue_dir, rogue_keys) = key_dir("rogue-own", &["ugv1"]);
    let mut insider_config = LinkConfig::new("city", RobotId::new("ugv1"));
    insider_config.listen = vec![format!("tcp/127.0.0.1:{}", ports[3])];
    insider_config.connect = vec![format!("tcp/127.0.0.1:{}", ports[0]), format!("tcp/127.0.0.1:{}", ports[1])];
    insider_config.credentials =
        Some(Credentials { user: "ugv1".into(), ..keys.credentials(&RobotId::new("ugv1")).unwrap() });
    let insider = TeamLink::open(&insider_config).unwrap();
    let mut fake = TeamState::new(RobotId::new("ugv1"), 0, TeamStateParams::default()).unwrap();
    fake.set_security(Arc::new(rogue_keys.security(&RobotId::new("ugv1")).unwrap())).unwrap();
    let fake_goal = fake.identify_goal(Point2::new(40.0, 5.5), GoalOrigin::Detected, Time::ZERO).unwrap();
    fake.claim(fake_goal.id(), Time::from_secs_f64(1e6)).unwrap();
    fake.mark_visited(fake_goal.id(), Time::from_secs_f64(1.0)).unwrap();

    let before: Vec<TeamState> = members.iter().map(|m| m.state.clone()).collect();
    let ugv2 = RobotId::new("ugv2");
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(4) {
        for link in [&outsider, &insider] {
            if let Some(m) = fake.make_sync(&ugv2, TierSet::ALL, usize::MAX) {
                link.send(&ugv2, spomp_teamstate::Tier::Coordination, m.encode());
            }
            fake.reset_peer(&ugv2);
        }
        // Only the members' own receive/apply; they say nothing new themselves.
        for m in members.iter_mut() {
            let Some(link) = &m.link else { continue };
            for (from, bytes) in link.receive() {
                if m.state.apply_bytes(&from, &bytes).is_err() {
                    m.rejected += 1;
                }
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    for (m, b) in members.iter().zip(&before) {
        assert!(m.state.same_records(b), "{} changed", m.state.self_id());
    }
    assert!(members[1].state.goal(g.id()).unwrap().visited.is_none());
    assert!(members[1].rejected > 0, "the insider's forgeries arrived and were refused");
    assert!(!outsider.reachable().contains(&ugv2), "the outsider met the team");
    let _ = std::fs::remove_dir_all(dir);
    let _ = std::fs::remove_dir_all(rogue_dir);
}
