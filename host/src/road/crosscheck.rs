//! The cross-check of Tangent's MPD against captif-slp, CAPTIF's published ISO 13473-1:2019
//! implementation (`tools/road_crosscheck.py`; `docs/road.md`, "Cross-check").

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{anyhow, Context, Result};
use tangent_core::real::Vec2;

/// The script, relative to the repository root.
pub const SCRIPT: &str = "tools/road_crosscheck.py";

/// Writes a raw profile as the script reads it: positions from `start` (mm), heights (mm),
/// drop-outs empty — only the samples the MPD chain itself reads, those within
/// `[start, start + length]`. A sample beyond the window (the road head's last column can
/// fall a few µm past it) would make captif-slp open one more 0.5 mm bin, held at the last
/// height if the sample is a drop-out, and that bin changes its filter's end: 0.011 mm on one
/// worn-concrete profile (`docs/road.md`, "Cross-check against captif-slp").
pub fn write_profile_csv(path: &Path, profile: &[Vec2], start: f64, length: f64) -> Result<()> {
    let mut text = String::from("distance_mm,relative_height_mm\n");
    let in_window = |p: &&Vec2| p.x >= start && p.x <= start + length;
    for p in profile.iter().filter(in_window) {
        let s = (p.x - start) * 1e3;
        if p.y.is_finite() {
            text += &format!("{s:.6},{:.6}\n", p.y * 1e3);
        } else {
            text += &format!("{s:.6},\n");
        }
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// captif-slp's MPD (metres) of each CSV, or `Ok(Err(reason))` when Python or the package
/// is not there (the caller skips and says why).
pub fn captif_mpd(
    repo: &Path,
    files: &[PathBuf],
) -> Result<std::result::Result<BTreeMap<PathBuf, Option<f64>>, String>> {
    let output = match Command::new("python3")
        .arg(repo.join(SCRIPT))
        .args(files)
        .output()
    {
        Ok(o) => o,
        Err(e) => return Ok(Err(format!("python3 not runnable: {e}"))),
    };
    if output.status.code() == Some(3) {
        return Ok(Err(String::from_utf8_lossy(&output.stderr)
            .trim()
            .to_string()));
    }
    if !output.status.success() {
        return Err(anyhow!(
            "{SCRIPT} failed: {}",
            String::from_utf8_lossy(&output.stderr)
        ));
    }
    let json: serde_json::Value =
        serde_json::from_slice(&output.stdout).context("reading the script's JSON")?;
    let mut out = BTreeMap::new();
    for f in files {
        let key = f.to_string_lossy();
        let mpd = json
            .get(key.as_ref())
            .ok_or_else(|| anyhow!("no result for {key}"))?
            .get("mpd_mm")
            .and_then(|v| v.as_f64())
            .map(|mm| mm * 1e-3);
        out.insert(f.clone(), mpd);
    }
    Ok(Ok(out))
}
