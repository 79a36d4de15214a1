//! `tangent study …`: studies that generate the tables in `docs/`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context as _;
use clap::Subcommand;
use tangent_host::study;

/// Arguments of `tangent study`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    which: Which,
}

#[derive(Subcommand, Debug)]
enum Which {
    /// Bias and noise of the subpixel peak estimators (thesis Table 5.1); writes the
    /// Markdown report (`docs/subpixel-study.md`).
    Subpixel {
        /// Write the report here instead of standard output.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Noise trials per sub-pixel offset for the random conditions.
        #[arg(long, default_value_t = study::StudyConfig::default().trials)]
        trials: usize,
        /// Sub-pixel offsets spanning one pixel.
        #[arg(long, default_value_t = study::StudyConfig::default().offsets)]
        offsets: usize,
    },
}

/// Runs `tangent study`. Exits with failure when the default estimator misses its
/// requirement, so the command doubles as a check.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    match args.which {
        Which::Subpixel {
            out,
            trials,
            offsets,
        } => {
            anyhow::ensure!(
                trials >= 2 && offsets >= 1,
                "need ≥ 2 trials and ≥ 1 offset"
            );
            let t0 = Instant::now();
            let result = study::run(study::StudyConfig { offsets, trials });
            let md = study::to_markdown(&result);
            match &out {
                Some(path) => std::fs::write(path, &md)
                    .with_context(|| format!("writing {}", path.display()))?,
                None => print!("{md}"),
            }
            let ok = study::requirement(&result).iter().all(|r| r.ok);
            eprintln!(
                "subpixel study: {:.1} s, default estimator requirement {}{}",
                t0.elapsed().as_secs_f64(),
                if ok { "met" } else { "NOT met" },
                out.map(|p| format!(", wrote {}", p.display()))
                    .unwrap_or_default()
            );
            Ok(if ok {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            })
        }
    }
}
