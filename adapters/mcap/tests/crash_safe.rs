//! A log written by `Recorder::create` is a complete MCAP file after every chunk, and a log cut
//! at any byte reads to its last whole chunk (`check_log`) and recovers (`recover_log`).

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::PathBuf;

use spomp_core::{Pose2, Time};
use spomp_mcap::{McapLog, Recorder, RecorderOptions, check_log, recover_log};

fn temp_log(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("spomp-crash-safe-{}-{name}.mcap", std::process::id()))
}

fn on_disk(path: &PathBuf) -> Vec<u8> {
    std::fs::read(path).unwrap()
}

#[test]
fn the_file_is_a_complete_log_after_every_chunk() {
    let path = temp_log("chunks");
    let options = RecorderOptions { chunk_bytes: 300, ..RecorderOptions::default() };
    let mut rec = Recorder::create(&path, options).unwrap();
    // Before any message: a valid, empty log.
    assert_eq!(McapLog::from_bytes(on_disk(&path)).messages().unwrap().len(), 0);
    let mut last_on_disk = 0;
    let mut grew = 0;
    for k in 0..200 {
        rec.pose("ugv1", Time::from_millis(k * 100), Pose2::new(k as f64, 0.0, 0.0), 0.0).unwrap();
        // At every moment between writes the file reads as a whole log, linearly.
        let bytes = on_disk(&path);
        let n = McapLog::from_bytes(bytes.clone()).messages().unwrap().len();
        let check = check_log(&bytes).unwrap();
        assert!(!check.closed);
        assert_eq!(check.lost_bytes, 0);
        assert_eq!(check.messages() as usize, n);
        assert!(n as i64 <= k + 1 && n >= last_on_disk, "k {k}: {n} on disk");
        if n > last_on_disk {
            grew += 1;
        }
        last_on_disk = n;
    }
    assert!(grew >= 10, "chunks were written as the run went ({grew} writes)");
    assert!(last_on_disk >= 190, "at most one chunk behind: {last_on_disk}");
    rec.finish().unwrap();
    let bytes = on_disk(&path);
    let check = check_log(&bytes).unwrap();
    assert!(check.closed);
    assert_eq!(check.messages(), 200);
    assert_eq!(McapLog::from_bytes(bytes).messages().unwrap().len(), 200);
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn chunks_span_a_bounded_log_time() {
    let path = temp_log("duration");
    let options = RecorderOptions { chunk_bytes: u64::MAX, chunk_duration_s: 1.0, ..RecorderOptions::default() };
    let mut rec = Recorder::create(&path, options).unwrap();
    for k in 0..=10 {
        rec.pose("ugv1", Time::from_millis(k * 100), Pose2::default(), 0.0).unwrap();
    }
    // 0.0 … 1.0 s: the eleventh message closes the first chunk.
    assert_eq!(check_log(&on_disk(&path)).unwrap().messages(), 11);
    rec.pose("ugv1", Time::from_millis(1100), Pose2::default(), 0.0).unwrap();
    assert_eq!(check_log(&on_disk(&path)).unwrap().messages(), 11);
    drop(rec); // no finish: the file stays as the last chunk left it
    let check = check_log(&on_disk(&path)).unwrap();
    assert!(!check.closed);
    assert_eq!(check.messages(), 11);
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn a_log_cut_at_any_byte_reads_to_its_last_whole_chunk() {
    let path = temp_log("cut");
    let options = RecorderOptions { chunk_bytes: 400, ..RecorderOptions::default() };
    let mut rec = Recorder::create(&path, options).unwrap();
    for k in 0..60 {
        rec.pose("ugv1", Time::from_millis(k * 100), Pose2::new(k as f64, 1.0, 0.0), 0.0).unwrap();
        rec.command("ugv1", Time::from_millis(k * 100), spomp_core::Twist2 { v: 1.0, omega: 0.0 }).unwrap();
    }
    rec.finish().unwrap();
    let full = on_disk(&path);
    std::fs::remove_file(&path).unwrap();
    let mut previous = 0;
    for len in 8..=full.len() {
        let cut = &full[..len];
        let check = check_log(cut).unwrap();
        assert!(check.bad_record.is_none(), "cut at {len}: {:?}", check.bad_record);
        assert!(check.messages() >= previous, "cut at {len}: fewer messages than a shorter cut");
        previous = check.messages();
        let mut out = std::io::Cursor::new(Vec::new());
        let recovered = recover_log(cut, &mut out).unwrap();
        assert_eq!(recovered.messages(), check.messages());
        let again = check_log(out.get_ref()).unwrap();
        assert!(again.closed);
        assert_eq!(again.messages(), check.messages(), "cut at {len}");
    }
    assert_eq!(previous, 120);
    assert!(check_log(b"not a log").is_err());
}

/// A closed log of a few chunks, built once.
fn sample() -> &'static [u8] {
    static LOG: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    LOG.get_or_init(|| {
        let path = temp_log("sample");
        let options = RecorderOptions { chunk_bytes: 500, ..RecorderOptions::default() };
        let mut rec = Recorder::create(&path, options).unwrap();
        for k in 0..40 {
            rec.pose("ugv1", Time::from_millis(k * 100), Pose2::new(k as f64, 1.0, 0.0), 0.0).unwrap();
            rec.json("/team/events", Time::from_millis(k * 100), &serde_json::json!({ "k": k })).unwrap();
        }
        rec.finish().unwrap();
        let bytes = on_disk(&path);
        std::fs::remove_file(&path).unwrap();
        bytes
    })
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(2000))]
    /// Corrupt logs (bytes overwritten, then cut anywhere) are read to what is whole or refused
    /// with an error; `check_log` and `recover_log` never panic, and agree on the messages.
    #[test]
    fn corrupt_logs_never_panic(
        edits in proptest::collection::vec((0usize..20_000, proptest::prelude::any::<u8>()), 0..8),
        cut in 0usize..20_000,
    ) {
        let mut bytes = sample().to_vec();
        for (at, b) in edits {
            let n = bytes.len();
            bytes[at % n] = b;
        }
        let len = bytes.len();
        bytes.truncate(cut % (len + 1));
        if let Ok(check) = check_log(&bytes) {
            proptest::prop_assert!(check.messages() <= 80);
        }
        let mut out = std::io::Cursor::new(Vec::new());
        if let Ok(recovered) = recover_log(&bytes, &mut out) {
            proptest::prop_assert!(recovered.messages() <= 80);
            // What was recovered is a closed log that reads back whole.
            let again = check_log(out.get_ref()).unwrap();
            proptest::prop_assert!(again.closed);
            proptest::prop_assert_eq!(again.messages(), recovered.messages());
        }
    }
}

/// Found by the `mcap_log` fuzz target: a 6 kB log whose channel record declares a topic of
/// 4 294 967 293 bytes made the reader reserve 4 GB before noticing the record is shorter. The
/// field lengths are now checked against the record first: a clear error, no allocation.
#[test]
fn a_field_length_past_its_record_is_corrupt_not_a_huge_allocation() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/oom-channel-topic-4gb.mcap");
    let bytes = std::fs::read(path).unwrap();
    let err = McapLog::from_bytes(bytes.clone()).messages().unwrap_err().to_string();
    assert!(err.contains("declares more bytes than the record holds"), "{err}");
    // `log check` and `log recover` read only the data section, which here ends before the bad
    // record: they read what is there.
    let found = check_log(&bytes).unwrap();
    assert!(found.bad_record.clone().is_none_or(|(_, why)| why.contains("declares more bytes")));
    let mut out = std::io::Cursor::new(Vec::new());
    let recovered = recover_log(&bytes, &mut out).unwrap();
    assert_eq!(recovered.messages(), found.messages());
}
