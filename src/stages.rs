//! Where a `split` run's wall time goes, stage by stage: what reading the source takes (on its
//! own thread), what the producer thread spends waiting for rows and building the pyramid, how
//! long it waits for the encoders (they are the
//! bottleneck) and how long the encoders wait for it (it is), and the encoders' and the sink's
//! share. Measured on every run (a few clock reads per source row and per batch of tiles) and
//! reported by `split --json` under `stages`, so that a benchmark can say which stage bounds a
//! run without a profiler.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// The clocks of one run, shared by the producer thread and the encoders' caller.
#[derive(Debug, Default)]
pub(crate) struct StageClock {
    read: AtomicU64,
    read_wait: AtomicU64,
    producer: AtomicU64,
    producer_blocked: AtomicU64,
    handoff: AtomicU64,
    cutter: AtomicU64,
    cut_wait: AtomicU64,
    encoders_idle: AtomicU64,
    encode: AtomicU64,
    store: AtomicU64,
    /// What the stages hold, part by part (`--json`'s `memory`).
    pub(crate) memory: crate::limits::Gauge,
}

/// One of [`StageClock`]'s clocks.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Stage {
    /// Reading and decoding source rows, on the source's own thread (`source::read_ahead`).
    Read,
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

    fn clock(&self, stage: Stage) -> &AtomicU64 {
        match stage {
            Stage::Read => &self.read,
            Stage::ReadWait => &self.read_wait,
            Stage::Producer => &self.producer,
            Stage::ProducerBlocked => &self.producer_blocked,
            Stage::Handoff => &self.handoff,
            Stage::Cutter => &self.cutter,
            Stage::CutWait => &self.cut_wait,
            Stage::EncodersIdle => &self.encoders_idle,
            Stage::Encode => &self.encode,
            Stage::Store => &self.store,
        }
    }

    /// Runs `f`, adding its wall time to `stage`.
    pub(crate) fn time<R>(&self, stage: Stage, f: impl FnOnce() -> R) -> R {
        let started = Instant::now();
        let result = f();
        self.add(stage, started.elapsed());
        result
    }

    /// Adds `d` to `stage` (a time measured elsewhere).
    pub(crate) fn add(&self, stage: Stage, d: Duration) {
        let nanos = u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        self.clock(stage).fetch_add(nanos, Ordering::Relaxed);
    }

    fn get(&self, stage: Stage) -> Duration {
        Duration::from_nanos(self.clock(stage).load(Ordering::Relaxed))
    }

    pub(crate) fn times(&self) -> StageTimes {
        let producer = self.get(Stage::Producer);
        let (read_wait, blocked) = (self.get(Stage::ReadWait), self.get(Stage::ProducerBlocked));
        let cutter = self.get(Stage::Cutter);
        // With a cutting thread, the producer's sends to the encoders are the cutter's.
        let (producer_waits, cutter_waits) = match cutter.is_zero() {
            true => (read_wait + blocked, Duration::ZERO),
            false => (read_wait + self.get(Stage::Handoff), self.get(Stage::CutWait) + blocked),
        };
        StageTimes {
            read: self.get(Stage::Read),
            read_wait,
            pyramid: producer.saturating_sub(producer_waits),
            cut: cutter.saturating_sub(cutter_waits),
            producer_blocked: blocked,
            encoders_idle: self.get(Stage::EncodersIdle),
            encode: self.get(Stage::Encode),
            store: self.get(Stage::Store),
        }
    }
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pyramid_is_what_the_producer_spends_not_waiting() {
        let clock = StageClock::new();
        clock.clock(Stage::Producer).store(10_000, Ordering::Relaxed);
        clock.clock(Stage::ReadWait).store(3_000, Ordering::Relaxed);
        clock.clock(Stage::ProducerBlocked).store(2_000, Ordering::Relaxed);
        let t = clock.times();
        assert_eq!(
            (t.read_wait, t.pyramid, t.producer_blocked),
            (Duration::from_nanos(3_000), Duration::from_nanos(5_000), Duration::from_nanos(2_000))
        );
        assert_eq!(clock.time(Stage::Store, || 7), 7);
        assert!(clock.times().store > Duration::ZERO);
    }
}
