//! Calibration tests (scratch; replaced below).
use std::path::PathBuf;
use tangent_host::calibrate::{corners, refine, Board};

#[test]
fn opencv_left() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/data/opencv-left");
    let board = Board::parse("9x6", "25mm").unwrap();
    let mut files: Vec<_> = std::fs::read_dir(&dir).unwrap().filter_map(|e| e.ok()).map(|e| e.path()).filter(|p| p.extension().map_or(false, |e| e == "jpg")).collect();
    files.sort();
    let mut views = vec![];
    for f in &files {
        let img = image::open(f).unwrap().to_luma8();
        match corners::detect(&img, &board, &f.display().to_string()) {
            Ok(v) => { println!("{}: {} corners", f.display(), v.corners.len()); views.push(v) }
            Err(e) => println!("{}: {e}", f.display()),
        }
    }
    let c = refine::calibrate_camera(&views, &board).unwrap();
    println!("{:?}\ninitial {:?}\nrms {} sigma {} std {:?} iters {} per view {:?} outliers {:?}", c.camera, c.initial, c.rms, c.sigma, c.std_dev, c.iterations, c.per_view_rms, c.outlier_views);
}
