//! Helpers of the tests that start `spomp` processes talking ROS 2 (the robot farm, the team
//! link): the command with DDS kept on this machine, a child reaped however the test ends, a
//! bounded wait, the child's output.
#![allow(dead_code)]

use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant};

/// `spomp` run from the workspace, its DDS discovery restricted to 127.0.0.1
/// (`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`), no inherited domain id.
pub fn spomp() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_spomp"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c.env("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST");
    c.env_remove("ROS_DOMAIN_ID");
    c
}

/// Kills the child when the test ends, however it ends.
pub struct Reap(pub Child);

impl Drop for Reap {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The child's exit status if it ends within `limit`.
pub fn wait_with_timeout(child: &mut Child, limit: Duration) -> Option<ExitStatus> {
    let deadline = Instant::now() + limit;
    while Instant::now() < deadline {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    None
}

/// What the child printed: (stdout, stderr).
pub fn output(child: &mut Child) -> (String, String) {
    use std::io::Read;
    let (mut out, mut err) = (String::new(), String::new());
    if let Some(mut s) = child.stdout.take() {
        let _ = s.read_to_string(&mut out);
    }
    if let Some(mut s) = child.stderr.take() {
        let _ = s.read_to_string(&mut err);
    }
    (out, err)
}
