//! `spomp replay`: a fresh robot fed a log's recorded inputs, its outputs compared with the
//! recorded ones message by message.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use spomp_behaviors::mission::limits::read_regular;
use spomp_mcap::replay::{ReplayOptions, ReplayReport};

/// The largest log replay reads, bytes (it holds it in memory).
const MAX_LOG_BYTES: u64 = 16 << 30;

/// Options of `spomp replay`.
#[derive(Debug, Clone, clap::Args)]
pub struct ReplayArgs {
    /// The log (`run.mcap` of `spomp sim --replayable`, or a robot's log).
    pub log: PathBuf,
    /// The robot to replay.
    #[arg(long)]
    pub robot: String,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    /// Print every node transition as it replays.
    #[arg(long)]
    pub trace: bool,
    /// Stop after this log time, seconds.
    #[arg(long, value_parser = crate::args::time_limit, allow_hyphen_values = true)]
    pub until: Option<f64>,
    /// Change a setting of the robot on replay: `navigation.SECTION.KEY=VALUE` (repeatable),
    /// e.g. `navigation.terrain.inflation_m=0.9`.
    #[arg(long = "set", value_name = "PATH=VALUE", value_parser = set)]
    pub sets: Vec<(String, String)>,
    /// The team's key folder, to replay a robot that signed its team state (`spomp run
    /// --keys`): the replay signs as it did, so its messages are the same bytes.
    #[arg(long, value_name = "DIR")]
    pub keys: Option<PathBuf>,
}

fn set(text: &str) -> Result<(String, String), String> {
    match text.split_once('=') {
        Some((k, v)) if !k.trim().is_empty() => Ok((k.trim().to_string(), v.trim().to_string())),
        _ => Err(format!("expected PATH=VALUE, got `{text}`")),
    }
}

/// Runs `spomp replay`: exit 0 when the replay is identical to the log, 1 at the first
/// divergence, 2 when the log cannot be replayed.
pub fn replay(
    args: &ReplayArgs,
    registry: &spomp_behaviors::NodeRegistry<spomp_robot::RobotRuntime>,
) -> Result<ExitCode> {
    let bytes = match read_regular(&args.log, MAX_LOG_BYTES) {
        Ok(b) => b,
        Err(e) => {
            errln!("error: {}: {e}", args.log.display());
            return Ok(ExitCode::from(2));
        }
    };
    let security = match &args.keys {
        None => None,
        Some(dir) => {
            let keys = spomp_zenoh::KeyDir::load(dir)
                .and_then(|k| k.security(&spomp_core::RobotId::new(&args.robot)))
                .map_err(|e| anyhow::anyhow!("--keys: {e}"));
            match keys {
                Ok(s) => Some(std::sync::Arc::new(s)),
                Err(e) => {
                    errln!("error: {e}");
                    return Ok(ExitCode::from(2));
                }
            }
        }
    };
    let options = ReplayOptions { robot: args.robot.clone(), until_s: args.until, sets: args.sets.clone(), security };
    let trace = args.trace;
    let mut print = |t: &spomp_behaviors::trace::TransitionRecord| {
        if trace {
            out!("{:>9.3}s {} {} {} -> {}", t.time.as_secs_f64(), options.robot, t.path, t.from, t.to);
        }
    };
    let report = match spomp_mcap::replay::replay(&bytes, &options, registry, &mut print) {
        Ok(r) => r,
        Err(e) => {
            errln!("error: {}: {e}", args.log.display());
            return Ok(ExitCode::from(2));
        }
    };
    if args.json {
        out!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        out!("{}", describe(&report));
    }
    Ok(if report.identical { ExitCode::SUCCESS } else { ExitCode::from(1) })
}

fn describe(r: &ReplayReport) -> String {
    let mut s = format!(
        "{} (seed {}, recorded by {} with spomp {}): {} calls, {} ticks, {} node transitions, {} team messages \
         replayed to {:.1} s in {:.2} s ({:.0}x real time)\n",
        r.robot,
        r.seed,
        r.source,
        r.recorded_with,
        r.calls,
        r.ticks,
        r.transitions,
        r.team_messages,
        r.replayed_to_s,
        r.wall_s,
        r.speed
    );
    if r.truncated {
        s.push_str(&format!("the log was cut short (not closed): replayed up to its end at {:.1} s\n", r.log_end_s));
    }
    match &r.divergence {
        None => s.push_str("identical"),
        Some(d) => {
            s.push_str(&format!("DIVERGED at {:.3} s on {}\n", d.time_s, d.channel));
            s.push_str(&format!("  recorded: {}\n  replayed: {}", d.recorded, d.replayed));
            if !d.node_path.is_empty() {
                s.push_str(&format!("\n  node: {}", d.node_path));
            }
        }
    }
    s
}
