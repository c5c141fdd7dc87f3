//! [`Plan::resumable`]: a run of one pack, tile directory or Deep Zoom output made resumable
//! (`split --resume`, docs/resume.md): what it is ([`Identity`]), its journal, and what it
//! takes over of an interrupted run of it. [`super::write`] hands both to the output's sink.

use std::hash::Hasher;
use std::path::{Path, PathBuf};

use super::{Format, Plan};
use crate::error::Result;
use crate::fnv::Fnv;
use crate::formats::viewer::Viewer;
use crate::resume::{Identity, Interrupted, Journal, ResumeError, Staging};
use crate::store::ObjectUrl;

/// A resumable run's journal, and what it took over of an interrupted run.
#[derive(Debug)]
pub(super) struct Resuming {
    pub journal: Journal,
    pub previous: Option<Interrupted>,
}

/// What [`Plan::resumable`] found beside the output.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct Resumed {
    /// This run's journal.
    pub journal: PathBuf,
    /// The interrupted run's journal, as found; `None`: there was nothing to resume, and the
    /// run starts afresh (journaled, so that it can be resumed in turn).
    pub from: Option<PathBuf>,
    /// Tiles that journal records as finished; each is checked against the staged output as
    /// the run starts, and made again if it is not whole.
    pub recorded: u64,
}

impl Plan {
    /// Makes the run resumable (`split --resume`): its one output (a pack, a tile directory
    /// or Deep Zoom, on local disk) is journaled as it is written, and where an interrupted
    /// run of the same command left its journal and staged output beside the destination, they
    /// are taken over now (so that the clean-up of dead runs' temporaries leaves them alone):
    /// [`Plan::write`] then keeps the tiles that are whole and makes only the others. A
    /// journal of another run (another input, other options, another version) is refused,
    /// naming what differs; the error is [`ResumeError`]. `input` is the file or directory
    /// the source was opened from: its fingerprint is part of the run's identity.
    pub fn resumable(&mut self, input: &Path) -> Result<Resumed> {
        let [planned] = self.outputs.as_slice() else {
            let output = self.outputs.first().map(|p| p.output.path.clone()).unwrap_or_default();
            let why =
                format!("resumes a run of one output; this one writes {}: run each on its own", self.outputs.len());
            return Err(ResumeError::Unsupported { output, why }.into());
        };
        let path = &planned.output.path;
        let unsupported = |why: String| ResumeError::Unsupported { output: path.clone(), why };
        let staging = match planned.output.format {
            Format::Pack => Staging::Pack,
            Format::Tiles | Format::Viewer(Viewer::Dzi) => Staging::Directory,
            other => {
                return Err(unsupported(format!(
                    "cannot resume a {} output yet; it resumes a pack (--pack FILE, -o FILE.vtpk), a tile directory (--layout vortex) or Deep Zoom (--layout dzi)",
                    other.name()
                ))
                .into());
            }
        };
        if ObjectUrl::of_path(path).is_some() {
            return Err(unsupported("resumes outputs on local disk; an s3:// output is not resumed yet".into()).into());
        }
        let o = &planned.opts;
        // Every other setting of the output (file names, its info.json or descriptor, a kept
        // profile), as one hash: the options above are named one by one in a refusal.
        let mut rest = Fnv::default();
        rest.write(format!("{:?}", planned.work).as_bytes());
        let identity = Identity::new()
            .with("vortex-tiler", env!("CARGO_PKG_VERSION"))
            .with("format", planned.output.format.name())
            .with("input fingerprint", crate::shard::fingerprint(input)?)
            .with("image", format!("{}x{}", planned.layout.width, planned.layout.height))
            .with("tile size", o.tile_size)
            .with("border", o.border)
            .with("codec", format!("{:?}", o.codec))
            .with("background", format!("{:?}", o.background))
            .with("flatten", o.flatten)
            .with("tile type", format!("{:?}", o.tile_depth))
            .with("filter", o.filter)
            // The stripes, and so a pack's order, depend on it.
            .with("max memory", o.max_memory)
            .with("levels down to one texel", o.down_to_one_texel)
            .with("re-encoding", format!("{:?}", o.reencode))
            .with("pack alignments", format!("{}/{}", self.pack.alignment, self.pack.payload_alignment))
            .with("other settings", format!("{:016x}", rest.finish()));
        let (journal, previous) = Journal::start(&planned.claim.path, staging, &identity)?;
        let resumed = Resumed {
            journal: journal.path().to_path_buf(),
            from: previous.as_ref().map(|p| p.journal.clone()),
            recorded: previous.as_ref().map_or(0, |p| p.records.len() as u64),
        };
        self.resume = Some(Resuming { journal, previous });
        Ok(resumed)
    }
}
