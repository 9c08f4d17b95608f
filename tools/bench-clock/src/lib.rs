//! Thread CPU time as a criterion measurement.
//!
//! On a shared or loaded machine, wall-clock time includes the time the benchmark thread waited
//! for a core; the thread's CPU time does not, so bars stated "on one core" can be checked there.
//! Benchmarks pick the clock at run time: `SPOMP_BENCH_CLOCK=cpu cargo bench …` measures CPU
//! time, anything else wall time.

use std::time::Duration;

use cpu_time::ThreadTime;
use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{Criterion, Throughput};

/// CPU time consumed by the benchmark thread.
pub struct ThreadCpuTime;

/// Formats CPU nanoseconds with a visible `(cpu)` tag so figures are not mistaken for wall time.
struct CpuFormatter;

impl CpuFormatter {
    fn unit(typical_ns: f64) -> (f64, &'static str) {
        match typical_ns {
            t if t < 1e3 => (1.0, "ns (cpu)"),
            t if t < 1e6 => (1e-3, "µs (cpu)"),
            t if t < 1e9 => (1e-6, "ms (cpu)"),
            _ => (1e-9, "s (cpu)"),
        }
    }
}

impl ValueFormatter for CpuFormatter {
    fn scale_values(&self, typical: f64, values: &mut [f64]) -> &'static str {
        let (factor, unit) = Self::unit(typical);
        values.iter_mut().for_each(|v| *v *= factor);
        unit
    }

    fn scale_throughputs(&self, _typical: f64, throughput: &Throughput, values: &mut [f64]) -> &'static str {
        // Report time per element: the figure bars are stated in (ns per node tick, …).
        let per = match throughput {
            Throughput::Elements(n) => *n,
            Throughput::ElementsAndBytes { elements, .. } => *elements,
            _ => return "ns (cpu)",
        }
        .max(1) as f64;
        values.iter_mut().for_each(|v| *v /= per);
        "ns (cpu) per element"
    }

    fn scale_for_machines(&self, _values: &mut [f64]) -> &'static str {
        "ns"
    }
}

impl Measurement for ThreadCpuTime {
    type Intermediate = ThreadTime;
    type Value = Duration;

    fn start(&self) -> ThreadTime {
        ThreadTime::now()
    }
    fn end(&self, start: ThreadTime) -> Duration {
        start.elapsed()
    }
    fn add(&self, a: &Duration, b: &Duration) -> Duration {
        *a + *b
    }
    fn zero(&self) -> Duration {
        Duration::ZERO
    }
    fn to_f64(&self, value: &Duration) -> f64 {
        value.as_nanos() as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        &CpuFormatter
    }
}

/// Whether the run asked for CPU time (`SPOMP_BENCH_CLOCK=cpu`).
pub fn cpu_clock_requested() -> bool {
    std::env::var("SPOMP_BENCH_CLOCK").is_ok_and(|v| v == "cpu")
}

/// Runs `bench` with the clock the run asked for, configured from the command line.
pub fn run_with_requested_clock(
    bench: impl Fn(&mut Criterion<ThreadCpuTime>),
    wall: impl Fn(&mut Criterion<WallTime>),
) {
    if cpu_clock_requested() {
        let mut c = Criterion::default().with_measurement(ThreadCpuTime).configure_from_args();
        bench(&mut c);
        c.final_summary();
    } else {
        let mut c = Criterion::default().configure_from_args();
        wall(&mut c);
        c.final_summary();
    }
}
