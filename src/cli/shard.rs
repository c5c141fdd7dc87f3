//! `split --shard` and `merge`: one split across machines (docs/scale-out.md).

use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use vortex_tiler::error::ShowPath;
use vortex_tiler::output::Product;
use vortex_tiler::scale_out::{self, ShardFiles, ShardJob};
use vortex_tiler::store::ObjectUrl;

use super::report;

/// `--shard`: `I/N`, or `auto` from the scheduler's environment.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ShardArg {
    Given { index: u32, count: u32 },
    Auto,
}

impl FromStr for ShardArg {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        if s == "auto" {
            return Ok(ShardArg::Auto);
        }
        let bad = || format!("'{s}' is not a shard: give I/N (shard I of N, counting from 0, e.g. 3/16) or auto");
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count): (u32, u32) = (i.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
        if count == 0 || index >= count {
            return Err(format!("shard '{s}': the index counts from 0 to N - 1 (N >= 1)"));
        }
        Ok(ShardArg::Given { index, count })
    }
}

/// Which shard this run makes, and where that was read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Chosen {
    pub index: u32,
    pub count: u32,
    /// `--shard I/N`, or the variables it came from.
    pub from: String,
}

impl ShardArg {
    /// The shard index and count: as given, or from a Slurm job array or a Kubernetes Indexed
    /// Job (`JOB_COMPLETION_INDEX`, with `--shards N`). In a Slurm array, with `--shards N`
    /// the task id is the index (so `--array=3,7` re-runs shards 3 and 7); without it the
    /// array must be one plain range, numbered from its first task, of
    /// `SLURM_ARRAY_TASK_COUNT` shards.
    pub fn choose(&self, shards: Option<u32>, env: impl Fn(&str) -> Option<String>) -> Result<Chosen> {
        let number = |name: &str| -> Result<Option<u32>> {
            env(name)
                .map(|v| v.trim().parse::<u32>().with_context(|| format!("{name}='{v}' is not a number")))
                .transpose()
        };
        let (index, count, from) = match self {
            ShardArg::Given { index, count } => {
                if shards.is_some_and(|n| n != *count) {
                    bail!("--shards {} contradicts --shard {index}/{count}", shards.unwrap_or(0));
                }
                (*index, *count, format!("--shard {index}/{count}"))
            }
            ShardArg::Auto => match (number("SLURM_ARRAY_TASK_ID")?, number("JOB_COMPLETION_INDEX")?) {
                (Some(id), _) => match shards {
                    Some(count) => (id, count, format!("SLURM_ARRAY_TASK_ID={id} of --shards {count}")),
                    None => {
                        let [min, max, step, count] =
                            ["MIN", "MAX", "STEP", "COUNT"].map(|v| number(&format!("SLURM_ARRAY_TASK_{v}")));
                        let (min, max, step) = (min?.unwrap_or(0), max?, step?.unwrap_or(1));
                        let count = count?
                            .context("--shard auto in a Slurm job without SLURM_ARRAY_TASK_COUNT: give --shards N")?;
                        if step != 1 || max.is_some_and(|max| max - min + 1 != count) {
                            bail!(
                                "--shard auto: this Slurm array is not one plain range ({count} tasks from {min} to {}, step {step}), so its tasks are not shards 0 to {}; give --shards N, and the task id is the shard index",
                                max.unwrap_or(min),
                                count - 1
                            );
                        }
                        let index = id.checked_sub(min).context("SLURM_ARRAY_TASK_ID is below SLURM_ARRAY_TASK_MIN")?;
                        (
                            index,
                            count,
                            format!("SLURM_ARRAY_TASK_ID={id} (array from {min}) of SLURM_ARRAY_TASK_COUNT={count}"),
                        )
                    }
                },
                (None, Some(index)) => {
                    let count = shards
                        .context("--shard auto in a Kubernetes Indexed Job: give --shards N (the Job's completions)")?;
                    (index, count, format!("JOB_COMPLETION_INDEX={index} of --shards {count}"))
                }
                (None, None) => bail!(
                    "--shard auto found neither SLURM_ARRAY_TASK_ID (a Slurm job array) nor JOB_COMPLETION_INDEX (a Kubernetes Indexed Job); give --shard I/N"
                ),
            },
        };
        if count == 0 || index >= count {
            bail!("shard {index} of {count} ({from}): the index must be below the count");
        }
        Ok(Chosen { index, count, from })
    }
}

/// `--pack` with `{shard}` replaced by the index, zero-padded to the count's width
/// (`out/part-{shard}.vtpk` -> `out/part-03.vtpk` of 16), so that one command line serves
/// every task of an array.
pub fn shard_path(pack: &Path, chosen: &Chosen) -> PathBuf {
    let width = (chosen.count - 1).to_string().len();
    let name = pack.to_string_lossy().replace("{shard}", &format!("{:0width$}", chosen.index));
    PathBuf::from(name)
}

impl Chosen {
    pub fn job<'a>(&self, input: &'a Path, info: String, pack: vortex_pack::WriteOptions) -> ShardJob<'a> {
        ShardJob { index: self.index, count: self.count, input, info, pack }
    }
}

#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// The shard packs of one split, written by `split --shard I/N --pack FILE`: all N of
    /// them, in any order. An s3://BUCKET/KEY.vtpk URL reads that object, and
    /// s3://BUCKET/PREFIX/ (with the trailing /) every object directly below the prefix; each
    /// is downloaded whole under TMPDIR before the merge (docs/scale-out.md).
    #[arg(value_name = "SHARD", required = true)]
    shards: Vec<PathBuf>,

    /// The pack to write: the pack `split --pack` of the same input and options makes, byte
    /// for byte. An existing pack is replaced; any other file only with --force. An
    /// s3://BUCKET/KEY.vtpk URL writes it as one object, streamed as it is made (one multipart
    /// upload, visible once complete; docs/object-storage.md).
    #[arg(short, long, value_name = "PACK")]
    output: PathBuf,

    /// Replace a regular file at --output that is not a pack.
    #[arg(long)]
    force: bool,

    #[command(flatten)]
    run: super::RunFlags,
}

pub fn run_merge(a: MergeArgs) -> Result<()> {
    let started = Instant::now();
    let names = ShardFiles::list(&a.shards)?;
    // The output is claimed before any shard is downloaded.
    let in_bucket = ObjectUrl::of_path(&a.output).is_some();
    match in_bucket {
        true => scale_out::claim_pack(&a.output, &names, a.force)?,
        false => {
            let inputs: Vec<&Path> = names.iter().map(PathBuf::as_path).collect();
            report::claim(&a.output, Product::Pack, &inputs, a.force)?;
        }
    }
    let downloads = names.iter().filter(|n| ObjectUrl::of_path(n).is_some()).count();
    if downloads > 0 && !a.run.quiet && !a.run.json {
        let packs = if downloads == 1 { "pack" } else { "packs" };
        eprintln!("downloading {downloads} shard {packs} under {}", std::env::temp_dir().shown());
    }
    let shards = ShardFiles::fetch(names)?;
    a.run.init_pool()?;
    // Every shard's level table is the merged pack's: the first one's gives the bar's length.
    let total = (shards.files().first().and_then(|first| vortex_pack::Pack::open(first).ok()))
        .map_or(0, |p| p.levels().iter().map(|l| l.tiles_w as u64 * l.tiles_h as u64).sum());
    let watch = a.run.watch(total)?;
    let merged = scale_out::merge_files(&shards, &a.output, &watch);
    watch.bar.finish_and_clear();
    let merged = merged?;
    let uploaded = in_bucket.then_some(merged.pack.file_bytes);
    let took = started.elapsed().as_secs_f64();
    let m = &merged;
    if a.run.json {
        let mut doc = serde_json::json!({
            "output": a.output.display().to_string(),
            "shards": m.shards,
            "cutLevel": m.cut,
            "madeAboveCut": m.made,
            "copiedBytes": m.copied_bytes,
            "sumsBytes": m.sums_bytes,
            "tiles": m.pack.tiles,
            "fileBytes": m.pack.file_bytes,
            "contentHash": format!("{:016x}", m.pack.content_hash),
            "seconds": took,
        });
        if let Some(sent) = uploaded {
            doc["uploadedBytes"] = sent.into();
        }
        say!("{doc}");
    } else if !a.run.quiet {
        say!("{}", report::pack_line(&m.pack));
        say!(
            "merged {} shards into {} in {took:.2} s: copied {} of payloads, made {} pages above the cut (LOD {}) from {} of sums",
            m.shards,
            a.output.shown(),
            report::mib(m.copied_bytes),
            m.made,
            m.cut,
            report::mib(m.sums_bytes),
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |name| vars.iter().find(|(k, _)| *k == name).map(|(_, v)| v.to_string())
    }

    #[test]
    fn shards_come_from_the_flag_or_the_scheduler() {
        let given = "3/16".parse::<ShardArg>().unwrap();
        assert_eq!(given.choose(None, env(&[])).unwrap().index, 3);
        assert!("16/16".parse::<ShardArg>().is_err() && "x".parse::<ShardArg>().is_err());
        let slurm = [
            ("SLURM_ARRAY_TASK_ID", "5"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_MAX", "8"),
            ("SLURM_ARRAY_TASK_COUNT", "8"),
        ];
        let c = ShardArg::Auto.choose(None, env(&slurm)).unwrap();
        assert_eq!((c.index, c.count), (4, 8));
        assert!(c.from.contains("SLURM_ARRAY_TASK_ID=5"));
        // With --shards the task id is the index: one failed shard re-run as `--array=5`.
        let rerun = [("SLURM_ARRAY_TASK_ID", "5"), ("SLURM_ARRAY_TASK_COUNT", "1")];
        let c = ShardArg::Auto.choose(Some(16), env(&rerun)).unwrap();
        assert_eq!((c.index, c.count), (5, 16));
        // A list or a step does not number the shards 0 to N - 1.
        let listed = [
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_MAX", "8"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ];
        assert!(ShardArg::Auto.choose(None, env(&listed)).unwrap_err().to_string().contains("plain range"));
        let stepped = [("SLURM_ARRAY_TASK_ID", "2"), ("SLURM_ARRAY_TASK_STEP", "2"), ("SLURM_ARRAY_TASK_COUNT", "4")];
        assert!(ShardArg::Auto.choose(None, env(&stepped)).unwrap_err().to_string().contains("--shards N"));
        let k8s = [("JOB_COMPLETION_INDEX", "2")];
        assert_eq!(ShardArg::Auto.choose(Some(4), env(&k8s)).unwrap().index, 2);
        assert!(ShardArg::Auto.choose(None, env(&k8s)).unwrap_err().to_string().contains("--shards"));
        assert!(ShardArg::Auto.choose(None, env(&[])).unwrap_err().to_string().contains("SLURM_ARRAY_TASK_ID"));
        assert!(ShardArg::Auto.choose(Some(2), env(&[("JOB_COMPLETION_INDEX", "2")])).is_err());
    }

    #[test]
    fn the_index_goes_into_the_pack_name() {
        let c = Chosen { index: 3, count: 16, from: String::new() };
        assert_eq!(shard_path(Path::new("out/part-{shard}.vtpk"), &c), PathBuf::from("out/part-03.vtpk"));
        assert_eq!(shard_path(Path::new("plain.vtpk"), &c), PathBuf::from("plain.vtpk"));
    }
}
