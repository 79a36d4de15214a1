//! Where the road MPD's positive bias comes from (`docs/accuracy.md`, road section, "The
//! selection-bias hypothesis checked"): on each surface, the MPD of the true profile read at
//! the measured columns (A), of A plus white noise of the measured column error's RMS, of A
//! plus the measured error moved to random positions, and of the measured profile; the
//! filtered error at the true peaks; its regression on the true profile; median pre-filters.
//!
//! `cargo run --release -p tangent-host --example road_bias` (the committed road captures);
//! `BIAS_SEEDS=91000,91001` adds simulated dense asphalt and worn concrete on those seeds,
//! `SHEET_W0_MM=0.68` simulates them with a sheet of that 1/e² half-width (no divergence; the
//! default is the road head's focused 0.25 mm sheet, 0.68 mm the collimated module's),
//! `NO_SPECKLE=1` without speckle, `BIAS_SKIP_COMMITTED=1` skips the committed captures;
//! `BIAS_SURFACES=surface-dressing,…` picks the simulated surfaces (by name); `BIAS_NO_MICRO=1`
//! renders them without microtexture, `=across` without the microtexture components running
//! across the line, `=along` without those along it (`docs/road.md`, "Relief finer than the
//! sheet"); `BIAS_DUMP=1` prints the columns about each segment's peaks.

use std::path::Path;

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;
use tangent_core::instrument::road::RoadParams;
use tangent_core::pipeline::PipelineConfig;
use tangent_core::real::Vec2;
use tangent_host::capture::Capture;
use tangent_host::measure::measure_road;
use tangent_host::road::{mpd_of_profile, true_profile, TRUTH_SPACING};
use tangent_host::simulate::road_corpus::{road_spec, Condition, Surface};
use tangent_host::simulate::simulate;

fn interp(t: &[Vec2], x: f64) -> f64 {
    let s0 = t[0].x;
    let f = (x - s0) / TRUTH_SPACING;
    let i = (f.floor() as isize).clamp(0, t.len() as isize - 2) as usize;
    let u = f - i as f64;
    t[i].y * (1.0 - u) + t[i + 1].y * u
}

fn mpd(p: &[Vec2], params: &RoadParams) -> f64 {
    mpd_of_profile(p, params)
        .map(|r| r.0.mpd)
        .unwrap_or(f64::NAN)
}

fn diag(name: &str, capture: &Capture) {
    let params = RoadParams::default();
    let o = measure_road(capture, None, &PipelineConfig::default(), &params).unwrap();
    let objects = &capture.meta.truth.as_ref().unwrap().objects;
    let t = true_profile(objects, &o.calibration, &params).unwrap();
    let m = &o.profile;
    let tc: Vec<Vec2> = m
        .iter()
        .map(|p| {
            Vec2::new(
                p.x,
                if p.y.is_finite() {
                    interp(&t, p.x)
                } else {
                    f64::NAN
                },
            )
        })
        .collect();
    let e: Vec<f64> = m.iter().zip(&tc).map(|(a, b)| a.y - b.y).collect();
    let ev: Vec<f64> = e.iter().copied().filter(|v| v.is_finite()).collect();
    let me = ev.iter().sum::<f64>() / ev.len() as f64;
    let se = (ev.iter().map(|v| (v - me).powi(2)).sum::<f64>() / ev.len() as f64).sqrt();
    let truth = mpd(&t, &params);
    let a = mpd(&tc, &params);
    let b = mpd(m, &params);
    // Filtered error.
    let (ma, sa, _, fm) = mpd_of_profile(m, &params).unwrap();
    let (_ta, st, _, ft) = mpd_of_profile(&tc, &params).unwrap();
    let fe: Vec<f64> = fm.iter().zip(&ft).map(|(a, b)| a - b).collect();
    let fme = fe.iter().sum::<f64>() / fe.len() as f64;
    let sf = (fe.iter().map(|v| (v - fme).powi(2)).sum::<f64>() / fe.len() as f64).sqrt();
    // Error at the measured peaks and at the true peaks (filtered, slope suppressed: differences
    // of the slope-suppressed profiles are the error minus its regression line).
    let idx =
        |s: f64| ((s - params.profile.window_start) / params.mpd.spacing).round() as isize - 1;
    let at = |s: f64| fe[(idx(s).clamp(0, fe.len() as isize - 1)) as usize] - fme;
    let e_meas_pk = (at(sa[0].peaks[0].x) + at(sa[0].peaks[1].x)) / 2.0;
    let e_true_pk = (at(st[0].peaks[0].x) + at(st[0].peaks[1].x)) / 2.0;
    if std::env::var("BIAS_DUMP").is_ok() {
        for pk in [
            st[0].peaks[0],
            st[0].peaks[1],
            sa[0].peaks[0],
            sa[0].peaks[1],
        ] {
            println!(
                "peak at {:+.3} mm (height {:.4} mm)",
                pk.x * 1e3,
                pk.y * 1e3
            );
            for (k, p) in m.iter().enumerate() {
                if (p.x - pk.x).abs() < 1.5e-3 {
                    let fk = idx(p.x).clamp(0, fe.len() as isize - 1) as usize;
                    println!(
                        "  col {k:4} x {:+8.3} meas {:+.4} truth {:+.4} err {:+6.1} µm | filtered meas {:+.4} truth {:+.4}",
                        p.x * 1e3, p.y * 1e3, tc[k].y * 1e3, (p.y - tc[k].y) * 1e6, fm[fk] * 1e3, ft[fk] * 1e3
                    );
                }
            }
        }
    }
    // True + white noise of the measured σ; true + the measured error circularly shifted.
    let mut rng = Pcg64::seed_from_u64(7);
    let normal = Normal::new(0.0, se).unwrap();
    let draws = 100;
    let mut cw = 0.0;
    for _ in 0..draws {
        let p: Vec<Vec2> = tc
            .iter()
            .map(|q| Vec2::new(q.x, q.y + normal.sample(&mut rng)))
            .collect();
        cw += mpd(&p, &params);
    }
    cw /= draws as f64;
    let n = ev.len();
    let mut cs = 0.0;
    let mut count = 0;
    for lag in (37..n).step_by(37) {
        let mut j = 0;
        let p: Vec<Vec2> = tc
            .iter()
            .map(|q| {
                if q.y.is_finite() {
                    let v = q.y + ev[(j + lag) % n] - me;
                    j += 1;
                    Vec2::new(q.x, v)
                } else {
                    *q
                }
            })
            .collect();
        cs += mpd(&p, &params);
        count += 1;
    }
    cs /= count as f64;
    let med = |p: &[Vec2], w: usize| -> Vec<Vec2> {
        (0..p.len())
            .map(|i| {
                if !p[i].y.is_finite() {
                    return p[i];
                }
                let lo = i.saturating_sub(w);
                let hi = (i + w + 1).min(p.len());
                let mut v: Vec<f64> = p[lo..hi]
                    .iter()
                    .map(|q| q.y)
                    .filter(|h| h.is_finite())
                    .collect();
                v.sort_by(|a, b| a.partial_cmp(b).unwrap());
                Vec2::new(p[i].x, v[v.len() / 2])
            })
            .collect()
    };
    // Filtered error regressed on the filtered true profile (a gain) and its curvature.
    let nf = ft.len();
    let mt = ft.iter().sum::<f64>() / nf as f64;
    let (mut stt, mut ste) = (0.0, 0.0);
    for k in 0..nf {
        stt += (ft[k] - mt).powi(2);
        ste += (ft[k] - mt) * (fe[k] - fme);
    }
    let gain = ste / stt;
    let (mut scc, mut sce) = (0.0, 0.0);
    for k in 1..nf - 1 {
        let c = ft[k - 1] - 2.0 * ft[k] + ft[k + 1];
        scc += c * c;
        sce += c * (fe[k] - fme);
    }
    let rest: f64 = (0..nf)
        .map(|k| (fe[k] - fme - gain * (ft[k] - mt)).powi(2))
        .sum::<f64>()
        / nf as f64;
    println!(
        "{name:28} gain of filtered error on filtered truth {:+.4} (residual σ {:.1} µm); curvature coefficient {:+.3} (corr {:+.2})",
        gain,
        rest.sqrt() * 1e6,
        sce / scc,
        sce / (scc.sqrt() * (fe.iter().map(|v| (v - fme).powi(2)).sum::<f64>()).sqrt())
    );
    let kurt = ev.iter().map(|v| (v - me).powi(4)).sum::<f64>() / ev.len() as f64 / se.powi(4);
    let out3 = ev.iter().filter(|v| (*v - me).abs() > 3.0 * se).count() as f64 / ev.len() as f64;
    let m1 = mpd(&med(m, 1), &params);
    let m2 = mpd(&med(m, 2), &params);
    let t1 = mpd(&med(&tc, 1), &params);
    let t2 = mpd(&med(&tc, 2), &params);
    println!(
        "{name:28} kurtosis {kurt:.1} >3σ {:.2}% | med3: meas {:+.4} clean {:+.4} | med5: meas {:+.4} clean {:+.4}",
        out3 * 100.0,
        (m1 - truth) * 1e3,
        (t1 - truth) * 1e3,
        (m2 - truth) * 1e3,
        (t2 - truth) * 1e3
    );
    println!(
        "{name:28} truth {:.4} err {:+.4} | sampling {:+.4} | meas-A {:+.4} | white(σ={:.1}µm) {:+.4} | shifted {:+.4} | σf {:.1}µm | e@measpk {:+.1}µm e@truepk {:+.1}µm | mpd(core) {:.4}",
        truth * 1e3,
        (b - truth) * 1e3,
        (a - truth) * 1e3,
        (b - a) * 1e3,
        se * 1e6,
        (cw - a) * 1e3,
        (cs - a) * 1e3,
        sf * 1e6,
        e_meas_pk * 1e6,
        e_true_pk * 1e6,
        ma.mpd * 1e3
    );
}

fn main() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/captures"));
    let committed = if std::env::var("BIAS_SKIP_COMMITTED").is_ok() {
        vec![]
    } else {
        vec![
            "road-head-dense-asphalt",
            "road-head-stone-mastic",
            "road-head-surface-dressing",
            "road-head-worn-concrete",
            "road-head-stone-mastic-wet",
            "road-head-dense-asphalt-polished",
            "road-head-piezo-0000um",
        ]
    };
    for c in committed {
        diag(c, &Capture::read(&root.join(c)).unwrap());
    }
    let seeds: Vec<u64> = std::env::var("BIAS_SEEDS")
        .ok()
        .map(|s| s.split(',').map(|v| v.parse().unwrap()).collect())
        .unwrap_or_default();
    for seed in seeds {
        let surfaces: Vec<Surface> = match std::env::var("BIAS_SURFACES") {
            Ok(names) => Surface::ALL
                .into_iter()
                .filter(|s| names.split(',').any(|n| n == s.name()))
                .collect(),
            Err(_) => vec![Surface::DenseAsphalt, Surface::WornConcrete],
        };
        for s in surfaces {
            let mut spec = road_spec(s, Condition::default(), seed);
            if let Ok(w) = std::env::var("SHEET_W0_MM") {
                spec.params.laser.waist_half_width_m = w.parse::<f64>().unwrap() * 1e-3;
                spec.params.laser.divergence_rad = 0.0;
            }
            if std::env::var("BIAS_NO_MICRO").is_ok() {
                for o in &mut spec.objects {
                    if let tangent_host::truth::Object::Road(r) = o {
                        // BIAS_NO_MICRO=across keeps the microtexture waves running along the
                        // line (|cos φ| > 0.5), =along those running across it.
                        let keep = std::env::var("BIAS_NO_MICRO").unwrap_or_default();
                        for w in &r.waves {
                            if w.wavelength_m < 0.5e-3 {
                                println!(
                                    "micro λ {:.3} mm direction {:.0}° along-line wavelength {:.2} mm",
                                    w.wavelength_m * 1e3,
                                    w.direction_rad.to_degrees(),
                                    w.wavelength_m / w.direction_rad.cos().abs() * 1e3
                                );
                            }
                        }
                        r.waves.retain(|w| {
                            let along = w.direction_rad.cos().abs() > 0.5;
                            w.wavelength_m >= 0.5e-3
                                || (keep == "across" && along)
                                || (keep == "along" && !along)
                        });
                    }
                }
            }
            if std::env::var("NO_SPECKLE").is_ok() {
                spec.params.speckle = false;
            }
            let (cap, _) = simulate(&spec).unwrap();
            diag(&format!("{} {seed}", s.name()), &cap);
        }
    }
}
