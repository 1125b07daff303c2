use moirecast_kernel::*;
struct Timer(std::sync::Mutex<(std::time::Instant, &'static str)>);
impl progress::Progress for Timer {
    fn stage(&self, name: &'static str, _t: u64) {
        let mut g = self.0.lock().unwrap();
        eprintln!("  {:<24} {:?}", g.1, g.0.elapsed());
        *g = (std::time::Instant::now(), name);
    }
}
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: f64 = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(20.0);
    let kind = args.get(2).cloned().unwrap_or("saddle".into());
    let surface = match kind.as_str() {
        "plane" => PitchSurface::Plane,
        "cyl" => PitchSurface::Cylinder { radius: 40.0 },
        "sphere" => PitchSurface::Sphere { radius: -80.0 },
        _ => PitchSurface::Saddle { radius: 60.0 },
    };
    let w = n * 0.5;
    let p = DesignParams {
        surface,
        width: w,
        height: w,
        period: 0.5,
        lens: LensParams {
            afov: 60f64.to_radians(),
            index: 1.41,
            rule: LensRule::ConstantAfov,
        },
        base: BaseParams {
            a: 0.0,
            d: None,
            levels: 1.0,
            afov: None,
        },
        profile: Profile::Rings {
            wavelength: w / 3.0,
        },
        tolerance: 0.002,
    };
    let d = Design::new(p).unwrap();
    let t = std::time::Instant::now();
    let timer = Timer(std::sync::Mutex::new((std::time::Instant::now(), "start")));
    let dm = mesher::mesh_device(&d, &timer).unwrap();
    progress::Progress::stage(&timer, "end", 0);
    eprintln!("mesh {:?} in {:?}", dm.stats, t.elapsed());
    let t = std::time::Instant::now();
    for c in check::solid_checks(&dm.mesh) {
        eprintln!("{c:?}");
    }
    eprintln!("solid checks {:?}", t.elapsed());
    let t = std::time::Instant::now();
    eprintln!("{:?}", measure::vertex_on_surface(&d, &dm, 7));
    eprintln!("{:?}", measure::surface_to_mesh(&d, &dm, 1));
    eprintln!("{:?}", measure::base_creases_follow_shift(&d, &dm));
    eprintln!("{:?}", measure::walls_on_outline(&d, &dm));
    eprintln!("{:?}", measure::creases_shared(&d, &dm));
    eprintln!("{:?}", measure::revealer_lens_stats(&d, &dm));
    eprintln!("measures {:?}", t.elapsed());
}
