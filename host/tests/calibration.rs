//! scratch
use std::path::PathBuf;
use tangent_host::calibrate::{corners, refine, Board, Corner, View};
use tangent_core::real::Vec2;

#[test]
fn opencv_left() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/data/opencv-left");
    let board = Board::parse("9x6", "25mm").unwrap();
    let csv = std::fs::read_to_string(dir.join("opencv_corners.csv")).unwrap();
    let mut cv: Vec<View> = vec![];
    for line in csv.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if cv.last().map_or(true, |v| v.name != f[0]) { cv.push(View { name: f[0].into(), width: 640, height: 480, corners: vec![] }); }
        cv.last_mut().unwrap().corners.push(Corner { i: f[1].parse().unwrap(), j: f[2].parse().unwrap(), pixel: Vec2::new(f[3].parse().unwrap(), f[4].parse().unwrap()) });
    }
    let c = refine::calibrate_camera(&cv, &board).unwrap();
    let k = c.camera;
    println!("ON OPENCV CORNERS: fx {:.3} fy {:.3} cx {:.3} cy {:.3} k {:?} rms {:.4} std {:.3?} views {:.2?}", k.fx, k.fy, k.cx, k.cy, k.distortion, c.rms, &c.std_dev, c.per_view_rms);
    for v in &cv {
        let img = image::open(dir.join(&v.name)).unwrap().to_luma8();
        let ours = corners::detect(&img, &board, &v.name).unwrap();
        // match by nearest
        let mut d = vec![];
        for o in &ours.corners { let m = v.corners.iter().map(|c| (c.pixel - o.pixel).norm()).fold(f64::MAX, f64::min); d.push(m); }
        d.sort_by(|a,b| a.total_cmp(b));
        println!("{}: n {} median {:.3} max {:.3}", v.name, d.len(), d[d.len()/2], d[d.len()-1]);
    }
}
#[test]
fn dump_bad() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/data/opencv-left");
    let board = Board::parse("9x6", "25mm").unwrap();
    let csv = std::fs::read_to_string(dir.join("opencv_corners.csv")).unwrap();
    let mut out = String::new();
    for line in csv.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let img = image::open(dir.join(f[0])).unwrap().to_luma8();
        let ours = corners::detect(&img, &board, f[0]).unwrap();
        let p = Vec2::new(f[3].parse().unwrap(), f[4].parse().unwrap());
        let m = ours.corners.iter().map(|c| (c.pixel - p).norm()).fold(f64::MAX, f64::min);
        if m > 0.05 { out += &format!("{} {} {}\n", f[0], f[1], f[2]); }
    }
    std::fs::write("/tmp/cvwork/bad.txt", out).unwrap();
}
