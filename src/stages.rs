//! Where a `split` run's time goes, stage by stage: what reading the source takes (on its
//! own thread), what decoding its tiles on the pool takes (a JPEG TIFF's bands decoded ahead),
//! what the producer thread spends waiting for rows and building the pyramid, how
//! long it waits for the encoders (they are the
//! bottleneck) and how long the encoders wait for it (it is), and the encoders' and the sink's
//! share. Measured on every run (a few clock reads per chunk of source rows, per batch of tiles
//! and per tile) and reported by `split --json` under `stages`, so that a benchmark can say
//! which stage bounds a run without a profiler. Each stage's CPU time is read beside its wall
//! time from the CPU clock of the thread that runs it (issue 28: CPU per source megapixel, the
//! work whatever the cores, is what compares with another tool).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// The clocks of one run, shared by the producer thread and the encoders' caller: each stage's
/// wall time and the CPU time of the thread that ran it, measured around the same calls.
#[derive(Debug, Default)]
pub(crate) struct StageClock {
    wall: [AtomicU64; STAGES],
    cpu: [AtomicU64; STAGES],
    /// What the stages hold, part by part (`--json`'s `memory`).
    pub(crate) memory: crate::limits::Gauge,
}

const STAGES: usize = Stage::Store as usize + 1;

/// One of [`StageClock`]'s clocks.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Stage {
    /// Reading and decoding source rows, on the source's own thread (`source::read_ahead`).
    Read,
    /// Decoding the source's tiles or strips in tasks on the pool, beside the reading thread
    /// (a JPEG TIFF's next band): the tasks' time over the pool's threads, as for encoding.
    Decode,
    /// The producer waiting for source rows.
    ReadWait,
    /// The producer's whole run, waits included.
    Producer,
    /// The thread that cuts tiles waiting to hand a batch of them to the encoders.
    ProducerBlocked,
    /// The producer waiting to hand a chunk of rows to the cutting thread, where the pyramid's
    /// sums and its cutting run on two (`split.rs`).
    Handoff,
    /// The cutting thread's whole run, waits included.
    Cutter,
    /// The cutting thread waiting for the producer's next chunk of rows.
    CutWait,
    /// Every encoder idle at once, waiting for tiles.
    EncodersIdle,
    /// Encoding (for sinks that store as tiles finish, storing too), per encoder thread: the
    /// tasks' time over the threads.
    Encode,
    /// Storing encoded tiles in order on the writer thread (ordered sinks: packs), beside the
    /// encoding of the next batch.
    Store,
}

impl StageClock {
    pub(crate) fn new() -> Arc<StageClock> {
        Arc::new(StageClock::default())
    }

    /// Runs `f`, adding its wall time to `stage` and the CPU time this thread spent in it
    /// (the CPU clock read inside the wall clock, so that a stage never has more CPU than wall).
    pub(crate) fn time<R>(&self, stage: Stage, f: impl FnOnce() -> R) -> R {
        self.time_all(&[stage], f)
    }

    /// As [`time`](Self::time), adding the same times to each of `stages` (a source row read
    /// on the producer's thread is both the reading and the producer's wait for it): one pair
    /// of clock reads instead of a pair per stage, in the loop over every row.
    pub(crate) fn time_all<R>(&self, stages: &[Stage], f: impl FnOnce() -> R) -> R {
        let started = Instant::now();
        let cpu = thread_cpu();
        let result = f();
        let cpu = cpu.zip(thread_cpu()).map(|(from, to)| to.saturating_sub(from));
        let wall = started.elapsed();
        for &stage in stages {
            self.add_cpu(stage, cpu.unwrap_or_default());
            self.add(stage, wall);
        }
        result
    }

    /// Adds `d` to `stage`'s wall time (a time measured elsewhere).
    pub(crate) fn add(&self, stage: Stage, d: Duration) {
        add(&self.wall[stage as usize], d);
    }

    /// Adds `d` to `stage`'s CPU time (measured elsewhere: the encoders' tasks, summed over
    /// the pool's threads).
    pub(crate) fn add_cpu(&self, stage: Stage, d: Duration) {
        add(&self.cpu[stage as usize], d);
    }

    pub(crate) fn times(&self) -> StageTimes {
        let wall = Split::of(&self.wall);
        let cpu = Split::of(&self.cpu);
        StageTimes {
            read: wall.read,
            decode: get(&self.wall, Stage::Decode),
            read_wait: wall.read_wait,
            pyramid: wall.pyramid,
            cut: wall.cut,
            producer_blocked: wall.blocked,
            encoders_idle: get(&self.wall, Stage::EncodersIdle),
            encode: get(&self.wall, Stage::Encode),
            store: get(&self.wall, Stage::Store),
            cpu: thread_cpu().map(|_| StageCpu {
                read: cpu.read,
                decode: get(&self.cpu, Stage::Decode),
                pyramid: cpu.pyramid,
                cut: cpu.cut,
                encode: get(&self.cpu, Stage::Encode),
                store: get(&self.cpu, Stage::Store),
            }),
        }
    }
}

/// Time spent in tasks on the pool, summed over the tasks: wall and CPU clock, each read on the
/// thread that runs the task. A source that decodes in such tasks keeps one
/// (`RowSource::decoding`); `source::read_ahead` adds what it counted in a pass to
/// [`Stage::Decode`].
#[derive(Debug, Default)]
pub(crate) struct TaskClock {
    wall: AtomicU64,
    cpu: AtomicU64,
}

impl TaskClock {
    /// Runs `f`, adding its wall time and this thread's CPU time in it.
    pub(crate) fn time<R>(&self, f: impl FnOnce() -> R) -> R {
        let started = Instant::now();
        let cpu = thread_cpu();
        let result = f();
        let cpu = cpu.zip(thread_cpu()).map(|(from, to)| to.saturating_sub(from));
        add(&self.cpu, cpu.unwrap_or_default());
        add(&self.wall, started.elapsed());
        result
    }

    /// The time counted so far.
    pub(crate) fn total(&self) -> Decoding {
        let get = |clock: &AtomicU64| Duration::from_nanos(clock.load(Ordering::Relaxed));
        Decoding { wall: get(&self.wall), cpu: get(&self.cpu) }
    }
}

/// Time a source has spent decoding in tasks on the pool since it was opened, summed over the
/// tasks (`RowSource::decoding`): the `decode` stage of a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Decoding {
    /// The tasks' wall time, added up.
    pub wall: Duration,
    /// Their CPU time (user and system), added up; zero where the platform has no per-thread
    /// CPU clock.
    pub cpu: Duration,
}

impl Decoding {
    /// What was spent after `earlier`, an earlier reading of the same source's clock.
    pub fn since(self, earlier: Decoding) -> Decoding {
        Decoding { wall: self.wall.saturating_sub(earlier.wall), cpu: self.cpu.saturating_sub(earlier.cpu) }
    }
}

/// Two sources' decoding together (channels read from several).
impl std::ops::Add for Decoding {
    type Output = Decoding;
    fn add(self, other: Decoding) -> Decoding {
        Decoding { wall: self.wall + other.wall, cpu: self.cpu + other.cpu }
    }
}

fn add(clock: &AtomicU64, d: Duration) {
    let nanos = u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
    clock.fetch_add(nanos, Ordering::Relaxed);
}

fn get(clocks: &[AtomicU64; STAGES], stage: Stage) -> Duration {
    Duration::from_nanos(clocks[stage as usize].load(Ordering::Relaxed))
}

/// The producer's and the cutter's runs less their waits, the same way for wall and CPU time
/// (a blocked thread spends next to no CPU, but a wait for rows read on the producer's own
/// thread is the reading's CPU, which is `read`'s, not the pyramid's).
struct Split {
    read: Duration,
    read_wait: Duration,
    pyramid: Duration,
    cut: Duration,
    blocked: Duration,
}

impl Split {
    fn of(clocks: &[AtomicU64; STAGES]) -> Split {
        let get = |stage| get(clocks, stage);
        let producer = get(Stage::Producer);
        let (read_wait, blocked) = (get(Stage::ReadWait), get(Stage::ProducerBlocked));
        let cutter = get(Stage::Cutter);
        // With a cutting thread, the producer's sends to the encoders are the cutter's.
        let (producer_waits, cutter_waits) = match cutter.is_zero() {
            true => (read_wait + blocked, Duration::ZERO),
            false => (read_wait + get(Stage::Handoff), get(Stage::CutWait) + blocked),
        };
        Split {
            read: get(Stage::Read),
            read_wait,
            pyramid: producer.saturating_sub(producer_waits),
            cut: cutter.saturating_sub(cutter_waits),
            blocked,
        }
    }
}

/// The CPU time (user and system) the calling thread has used since it started; `None` where
/// the platform has no clock for it (then `split --json` reports no CPU times).
#[cfg(any(target_os = "linux", target_os = "android", target_os = "macos", target_os = "freebsd"))]
#[expect(unsafe_code, reason = "clock_gettime, the one way to read a thread's CPU clock")]
pub(crate) fn thread_cpu() -> Option<Duration> {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec for the call to fill; nothing else is passed.
    let ok = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) } == 0;
    let (secs, nanos) = (u64::try_from(ts.tv_sec).ok()?, u32::try_from(ts.tv_nsec).ok()?);
    ok.then(|| Duration::new(secs, nanos))
}

#[cfg(not(any(target_os = "linux", target_os = "android", target_os = "macos", target_os = "freebsd")))]
pub(crate) fn thread_cpu() -> Option<Duration> {
    None
}

/// Wall time per stage of a finished run. The source is read on a thread of its own (`read`);
/// the producer's `read_wait + pyramid + producer_blocked` is its whole run, or, where a
/// thread of its own cuts the tiles, `pyramid` is the producer's sums and `cut` the cutting
/// (the cutter then is the one that waits for the encoders); the encoders' caller
/// spends `encoders_idle + encode` and the writer `store`. A run bound by reading shows a large `read_wait`; by
/// the pyramid, a large `encoders_idle` and little `read_wait`; by the encoders, a large
/// `producer_blocked` (and by the pack writer, a `store` longer than `encode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StageTimes {
    /// Reading and decoding the source (on its own thread).
    pub read: Duration,
    /// Decoding the source's tiles in tasks on the pool (a JPEG TIFF's bands decoded ahead of
    /// the reading thread), per pool thread: the tasks' time divided by the pool's threads.
    pub decode: Duration,
    /// The producer waiting for source rows.
    pub read_wait: Duration,
    /// Building the pyramid, and cutting tiles where `cut` is zero (the producer's time not
    /// waiting).
    pub pyramid: Duration,
    /// Cutting tiles on a thread of their own, beside the pyramid's sums (its time not waiting).
    pub cut: Duration,
    /// The producer waiting for the encoders to take a batch.
    pub producer_blocked: Duration,
    /// The encoders waiting for the producer.
    pub encoders_idle: Duration,
    /// Encoding (and, for unordered sinks, storing) on the pool.
    pub encode: Duration,
    /// Storing in order on the writer thread (packs), beside the encoding of the next batch.
    pub store: Duration,
    /// The CPU time of the same stages; `None` where the platform has no per-thread CPU clock.
    pub cpu: Option<StageCpu>,
}

/// CPU time (user and system) per stage of a finished run, read from the CPU clock of the
/// thread that runs each stage around the same calls as its wall time: the reading thread's
/// reading, the decoding tasks' and the encoding tasks' (summed over the pool's threads, not
/// divided by them as the wall time is), the producer's sums (and cutting where `cut` is
/// zero), the cutting thread's cutting and the writer's storing. Not counted: threads a source
/// decodes on besides its reading thread and the pool (a Deflate or LZW TIFF's strip workers),
/// tiles a source other than a JPEG TIFF decodes on the pool (JPEG 2000, NDPI, `convert`'s
/// inputs), the encoders' caller and the process's start and end; the process's CPU time is
/// the stages' and these.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StageCpu {
    pub read: Duration,
    pub decode: Duration,
    pub pyramid: Duration,
    pub cut: Duration,
    pub encode: Duration,
    pub store: Duration,
}

impl StageCpu {
    /// The stages' CPU time together.
    pub fn total(&self) -> Duration {
        self.read + self.decode + self.pyramid + self.cut + self.encode + self.store
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pyramid_is_what_the_producer_spends_not_waiting() {
        let clock = StageClock::new();
        clock.add(Stage::Producer, Duration::from_nanos(10_000));
        clock.add(Stage::ReadWait, Duration::from_nanos(3_000));
        clock.add(Stage::ProducerBlocked, Duration::from_nanos(2_000));
        let t = clock.times();
        assert_eq!(
            (t.read_wait, t.pyramid, t.producer_blocked),
            (Duration::from_nanos(3_000), Duration::from_nanos(5_000), Duration::from_nanos(2_000))
        );
        assert_eq!(clock.time(Stage::Store, || 7), 7);
        assert!(clock.times().store > Duration::ZERO);
    }

    #[test]
    fn the_cpu_of_a_stage_is_its_threads_and_no_more_than_its_wall_time() {
        let clock = StageClock::new();
        // Work the optimiser cannot drop: the thread's CPU clock must move.
        let sum = clock.time(Stage::Read, || (0..2_000_000u64).map(std::hint::black_box).sum::<u64>());
        assert_eq!(sum, 1_999_999_000_000);
        // A wait for rows read on this thread holds their reading: not the pyramid's.
        clock.time(Stage::Producer, || clock.time(Stage::ReadWait, || clock.time(Stage::Read, || ())));
        let t = clock.times();
        let Some(cpu) = t.cpu else {
            assert!(thread_cpu().is_none());
            return;
        };
        assert!(cpu.read > Duration::ZERO && cpu.read <= t.read, "{t:?}");
        assert_eq!((cpu.cut, cpu.encode, cpu.store), (Duration::ZERO, Duration::ZERO, Duration::ZERO));
        clock.add_cpu(Stage::Encode, Duration::from_millis(5));
        assert_eq!(clock.times().cpu.map(|c| c.encode), Some(Duration::from_millis(5)));
    }
}
