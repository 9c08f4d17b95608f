//! `spomp run`'s body: the mission's robot behind a ROS 2 node, its team link, recording and
//! live view (the `deploy` feature).

use std::io::{Seek, Write};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::{Context, Result, bail};
use spomp_behaviors::NodeRegistry;
use spomp_behaviors::mission::limits::{MAX_SOURCE_BYTES, read_text};
use spomp_behaviors::mission::{LoadOptions, MissionSection, load_mission_str, load_mission_with};
use spomp_core::RobotId;
use spomp_mcap::{Recorder, RecorderOptions, RobotConventions, SafeFile};
use spomp_robot::{Robot, RobotRuntime, RobotSetup};
use spomp_ros2::{RobotNode, RunSettings};

use crate::live::{Discard, LiveTap};
use crate::recording::{LogObserver, ObserverSettings};

use super::RunArgs;

/// Runs `spomp run`.
pub fn run(args: &RunArgs, registry: &NodeRegistry<RobotRuntime>) -> Result<ExitCode> {
    let options = LoadOptions { allowed_dirs: args.allow_dirs.clone() };
    let loaded = match &args.resolve_in {
        Some(dir) => {
            let text = match read_text(&args.mission, MAX_SOURCE_BYTES) {
                Ok(t) => t,
                Err(e) => {
                    errln!("error: {}: {e}", args.mission.display());
                    return Ok(ExitCode::from(1));
                }
            };
            let name = args.mission.file_name().map_or_else(|| "mission.yaml".into(), |n| n.to_os_string());
            load_mission_str(&text, &dir.join(name), registry, &options)
        }
        None => load_mission_with(&args.mission, registry, &options),
    };
    if !loaded.is_valid() {
        crate::commands::print_diagnostics(&loaded);
        return Ok(ExitCode::from(1));
    }
    let Some(mission) = loaded.mission.as_ref() else { bail!("mission did not load") };
    let mut settings = match RunSettings::from_mission(mission, &args.robot, args.domain_id) {
        Ok(s) => s,
        Err(e) => {
            errln!("error: --robot: {e}");
            return Ok(ExitCode::from(2));
        }
    };
    if !args.interfaces.is_empty() {
        settings.dds.interfaces = args.interfaces.clone();
    }
    let node = format!("{}/{}", settings.topics.namespace().trim_end_matches('/'), spomp_ros_msgs::ROBOT_NODE_NAME);
    let read = |p: &std::path::Path| std::fs::read_to_string(p).map_err(|e| e.to_string());
    let ros_args = match crate::ros_args::parse(&args.ros_args, &node, &read) {
        Ok(r) => r,
        Err(e) => {
            errln!("error: {e}");
            return Ok(ExitCode::from(2));
        }
    };
    // The command line's flag and the ROS parameter override the mission, as a launch file's
    // `use_sim_time` overrides a node's own default.
    if let Some(sim) = ros_args.use_sim_time {
        settings.use_sim_time = sim;
    }
    settings.use_sim_time |= args.use_sim_time || args.lockstep;
    if args.topics {
        for (role, name) in settings.topics.iter() {
            out!("{role:<18} {name}");
        }
        out!("{:<18} {}", "team/status", settings.topics.status());
        return Ok(ExitCode::SUCCESS);
    }
    // Before anything starts: an operator interface without the operator's key is refused.
    let operator_key = match (args.live_operator, &args.clicked_point) {
        (true, _) => Some(crate::operator_desk::operator_key(args.team_link.keys.as_deref(), "--live-operator")?),
        (false, Some(_)) => {
            Some(crate::operator_desk::operator_key(args.team_link.keys.as_deref(), "--clicked-point")?)
        }
        (false, None) => None,
    };
    let seed = args.seed.unwrap_or(spomp_world::SimSpec::of_mission(mission)?.first_seed());
    if args.lockstep {
        settings.lockstep = Some(spomp_ros2::settings::LockstepSettings { seed, timeout_s: args.lockstep_timeout_s });
    }
    // The operating area (map grid, class table, prior map) is the mission's world, as in `sim`.
    let world = spomp_world::world_for_mission(mission, &loaded.base_dir(), seed)
        .with_context(|| format!("building the operating area of `{}`", mission.mission))?;
    let area = spomp_world::operating_area(mission, &world)?;
    let setup = RobotSetup::from_mission(mission, &args.robot, &area, seed)
        .with_context(|| format!("setting up robot `{}`", args.robot))?;
    // What a replay of the log needs to build this robot again.
    let mut run_info = match &args.record {
        Some(_) => Some(
            spomp_mcap::replay::run_info(
                &loaded,
                "run",
                seed,
                &area,
                setup.config.map_publish_period_s(),
                setup.config.map_compression().level,
            )
            // The node runs the heavy skills on worker threads (spomp_ros2::workers).
            .map(|info| spomp_mcap::RunInfo { background_skills: true, ..info })?,
        ),
        None => None,
    };
    let mut robot =
        Robot::from_setup(&loaded, setup, registry).with_context(|| format!("setting up robot `{}`", args.robot))?;
    let simulated_session = robot.team().session();
    // A recorded robot records from its first call on: the resume from a state file included.
    robot.record_seam(args.record.is_some());
    let link = crate::team_link::set_up(&args.team_link, mission, &args.robot, &mut robot)?;
    if args.lockstep && link.link.is_none() {
        // Over the farm's radio the robot is one of the simulator's: its session is theirs (a
        // wall-clock session changes every message's bytes, hence what a link's budget carries).
        robot.set_team_session(simulated_session);
    }
    if let Some(info) = run_info.as_mut() {
        info.team_session = robot.team().session();
        info.team_secured = robot.team().security().is_some();
    }
    let mut peers: Vec<RobotId> =
        mission.team.iter().filter(|r| r.id != args.robot).map(|r| RobotId::new(&r.id)).collect();
    if link.link.is_some() {
        // The operator (`spomp operator`) joins the link like a robot: it is sent what it lacks
        // (the robots' acknowledgements above all) whenever it is reachable.
        peers.push(RobotId::new(spomp_teamstate::OPERATOR_ID));
    }
    let mut node = RobotNode::new(robot, settings.clone(), peers).context("starting the ROS 2 node")?;
    for n in &link.notes {
        errln!("{n}");
    }
    crate::team_link::plug(&mut node, link.link, &args.team_link, &args.robot);
    let mut live_points = None;
    if let Some(key) = operator_key {
        let (desk, queue) =
            crate::operator_desk::Desk::new(key, args.live_operator, spomp_robot::setup::team_params(mission))?;
        node.set_operator_desk(Box::new(desk), args.clicked_point.as_deref())
            .context("subscribing to the clicked-point topic")?;
        if let Some(topic) = &args.clicked_point {
            errln!(
                "operator: points on {topic} (map frame `{}`) become goals, signed as the operator's",
                settings.frames.map
            );
        }
        live_points = queue.map(|q| crate::operator_desk::live_handler(settings.frames.map.clone(), q));
    }

    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register_conditional_shutdown(sig, 130, stop.clone())
            .context("installing signal handlers")?;
        signal_hook::flag::register(sig, stop.clone()).context("installing signal handlers")?;
    }
    let live = match args.live {
        Some(addr) => {
            let options = spomp_live::LiveOptions { points: live_points };
            let takes_points = options.points.is_some();
            let name = format!("spomp run {} --robot {}", mission.mission, args.robot);
            let server = spomp_live::LiveServer::start_with(addr, &name, options)?;
            errln!("live view: {} (Foxglove: Open connection → Foxglove WebSocket; docs/live.md)", server.url());
            if takes_points {
                errln!(
                    "operator: points published from the viewer (3-D panel \"Publish point\", frame `{}`) become goals, signed as the operator's",
                    settings.frames.map
                );
            }
            Some(LiveTap::new(server))
        }
        None => None,
    };
    let options = RecorderOptions { panorama_downsample: 1, ..RecorderOptions::default() };
    // The log names, types and frames the robot's messages as its ROS 2 side does.
    let conventions = RobotConventions {
        frames: settings.frames.clone(),
        cmd_vel_type: settings.cmd_vel_type,
        tf: settings.topics.get("tf").to_string(),
        tf_static: settings.topics.get("tf_static").to_string(),
        depth_encoding: settings.depth_encoding,
        depth_scale_m: settings.depth_scale_m,
        logger: spomp_ros_msgs::rcl_logger_name(settings.topics.namespace(), spomp_ros_msgs::ROBOT_NODE_NAME),
    };
    if !args.json {
        errln!(
            "spomp run: robot {} on DDS domain {} ({}), {}; Ctrl-C stops it",
            args.robot,
            settings.dds.domain_id,
            if settings.dds.interfaces.is_empty() {
                "all interfaces".to_string()
            } else {
                settings.dds.interfaces.iter().map(ToString::to_string).collect::<Vec<_>>().join(", ")
            },
            match (&settings.lockstep, settings.use_sim_time) {
                (Some(_), _) => "in the farm's lockstep",
                (None, true) => "time from /clock",
                (None, false) => "wall-clock time",
            },
        );
        if !settings.dds.interfaces.is_empty() {
            let ports = settings.dds.rtps_ports();
            errln!(
                "note: {} (this domain: ports {}-{})",
                spomp_ros2::dds::RECEIVE_ON_ALL_INTERFACES,
                ports.start(),
                ports.end()
            );
        }
    }
    let (report, error) = match (&args.record, live) {
        (Some(path), live) => {
            let mut rec = Recorder::create(path, options).with_context(|| format!("creating {}", path.display()))?;
            rec.set_conventions(&args.robot, conventions);
            // In lockstep the farm's hello says whether the heavy skills run in the background:
            // the setup is written once it came.
            if let Some(info) = run_info.as_ref().filter(|_| !args.lockstep) {
                rec.run_info(info).with_context(|| format!("writing the run's setup to {}", path.display()))?;
            }
            if let Some(tap) = live {
                rec.set_tap(Box::new(tap));
            }
            let pending = run_info.filter(|_| args.lockstep);
            drive(&mut node, &stop, args.until_s, Some(rec), true, pending)?
        }
        (None, Some(tap)) => {
            // Only the live view wants the messages: recorded into nothing, uncompressed.
            let options = RecorderOptions { compress: false, ..options };
            let mut rec = Recorder::new(Discard::default(), options).context("starting the live view's recorder")?;
            rec.set_conventions(&args.robot, conventions);
            rec.set_tap(Box::new(tap));
            drive(&mut node, &stop, args.until_s, Some(rec), false, None)?
        }
        (None, None) => drive::<SafeFile>(&mut node, &stop, args.until_s, None, false, None)?,
    };
    if let Some(e) = error {
        return Err(e.context("recording"));
    }
    if args.json {
        out!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        out!(
            "robot {}: {:.1} s, {} ticks ({:.1}/s of {:.1}/s), {} overruns, longest tick {:.1} ms, longest panorama {:.1} ms",
            report.robot,
            report.robot_time_s,
            report.ticks,
            report.tick_rate_hz,
            report.target_tick_hz,
            report.tick_overruns,
            report.max_tick_ms,
            report.max_panorama_ms
        );
        out!(
            "latency: odometry → command {:.1} ms median, {:.1} ms p99; panorama → command {:.1} ms median, {:.1} ms p99",
            report.odometry_to_command_p50_ms,
            report.odometry_to_command_p99_ms,
            report.panorama_to_command_p50_ms,
            report.panorama_to_command_p99_ms
        );
        out!(
            "inputs: {} odometry, {} panoramas, {} poses, {} team; {} malformed, {} dropped; tree {}",
            report.received.odometry,
            report.received.panoramas,
            report.received.poses,
            report.received.team,
            report.malformed_inputs,
            report.dropped_inputs,
            report.tree_status
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Runs the node until it stops, recording into `recorder` if given (its seam calls too when
/// `replayable`); the report, and the error that stopped the recording if one did.
fn drive<W: Write + Seek>(
    node: &mut RobotNode,
    stop: &AtomicBool,
    until_s: Option<f64>,
    recorder: Option<Recorder<W>>,
    replayable: bool,
    pending_info: Option<spomp_mcap::RunInfo>,
) -> Result<(spomp_ros2::RunReport, Option<anyhow::Error>)> {
    let settings = ObserverSettings {
        // Every panorama the robot took.
        pano_every_ns: 1,
        panos_dir: None,
        bar: None,
        trace: false,
        replayable,
        classes: None,
    };
    let mut observer = LogObserver::new(recorder, settings).with_pending_info(pending_info);
    let report = node.run(stop, until_s, &mut observer);
    let (recorder, error) = observer.into_parts();
    if let Some(rec) = recorder {
        rec.finish().context("finishing the log")?;
    }
    Ok((report, error))
}
