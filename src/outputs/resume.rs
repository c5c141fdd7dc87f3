//! [`Plan::resumable`]: a run of one pack, tile directory or viewer layout made resumable
//! (`split --resume`, docs/resume.md): what it is ([`Identity`]), its journal, and what it
//! takes over of an interrupted run of it. [`super::write`] hands both to the output's sink.

use std::collections::HashMap;
use std::hash::Hasher;
use std::path::{Path, PathBuf};

use super::{Format, Plan};
use crate::error::Result;
use crate::fnv::Fnv;
use crate::resume::{Identity, Interrupted, Journal, ResumeError, Staging};
use crate::store::ObjectUrl;
use crate::store::staged::resumable_path;

/// A resumable run's record, and what it took over of an interrupted run.
#[derive(Debug)]
pub(super) enum Resuming {
    /// A local output, or a pack at `s3://` staged on this machine at `local`: the journal
    /// beside it, and what it took over.
    Journaled { journal: Journal, previous: Option<Interrupted>, local: Option<PathBuf> },
    /// A directory output at an `s3://` prefix: the bucket is the record. The run's identity
    /// (its marker names it while it writes) and every object an interrupted run of it left
    /// under the prefix, with its size; `None`: nothing to resume.
    Prefix { run: Identity, listed: Option<HashMap<String, u64>> },
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
    /// the run starts, and made again if it is not whole. At an `s3://` prefix: the objects
    /// listed under it.
    pub recorded: u64,
}

impl Plan {
    /// Makes the run resumable (`split --resume`): its one output (a pack, a tile directory
    /// or a viewer layout) is journaled as it is written, and where an interrupted run of the
    /// same command left its journal and staged output beside the destination, they are taken
    /// over now (so that the clean-up of dead runs' temporaries leaves them alone):
    /// [`Plan::write`] then keeps the tiles that are whole and makes only the others. A pack at
    /// an `s3://` URL is staged and journaled so on this machine, under the temporary
    /// directory. At an `s3://` prefix the bucket is the record: the prefix's marker names the
    /// run, and an interrupted run's tiles are those whose objects are listed there; `from`
    /// and `journal` are then the marker's URL. A journal or marker of another run (another
    /// input, other options, another version) is refused, naming what differs, before
    /// anything is written or deleted; the error is [`ResumeError`]. `input` is the file or directory
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
            Format::Tiles | Format::Viewer(_) => Staging::Directory,
            other => {
                return Err(unsupported(format!(
                    "cannot resume a {} output yet; it resumes a pack (--pack FILE, -o FILE.vtpk), a tile directory (--layout vortex) or a viewer layout (--layout dzi, iiif, xyz, google)",
                    other.name()
                ))
                .into());
            }
        };
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
        let url = ObjectUrl::of_path(path).transpose()?;
        let local = match (&url, staging) {
            (None, _) => None,
            (Some(url), Staging::Directory) => {
                let (marker, listed) = crate::store::resumable_prefix(url, &identity)?;
                let resumed = Resumed {
                    from: listed.as_ref().map(|_| marker.clone()),
                    journal: marker,
                    recorded: listed.as_ref().map_or(0, |l| l.len() as u64),
                };
                self.resume = Some(Resuming::Prefix { run: identity, listed });
                return Ok(resumed);
            }
            // Staged on this machine, journaled beside its staged file as a local pack is.
            (Some(url), Staging::Pack) => {
                let local = resumable_path(url);
                if let Some(dir) = local.parent() {
                    std::fs::create_dir_all(dir).map_err(|e| ResumeError::Io { path: dir.to_path_buf(), source: e })?;
                }
                Some(local)
            }
        };
        let dest = local.as_deref().unwrap_or(&planned.claim.path);
        let (journal, previous) = Journal::start(dest, staging, &identity)?;
        if local.is_some() {
            // What dead runs left there that was not taken over: nobody else cleans it up.
            crate::output::remove_stale(dest).map_err(|e| ResumeError::Io { path: dest.to_path_buf(), source: e })?;
        }
        let resumed = Resumed {
            journal: journal.path().to_path_buf(),
            from: previous.as_ref().map(|p| p.journal.clone()),
            recorded: previous.as_ref().map_or(0, |p| p.records.len() as u64),
        };
        self.resume = Some(Resuming::Journaled { journal, previous, local });
        Ok(resumed)
    }
}
