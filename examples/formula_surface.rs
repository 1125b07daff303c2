//! Build a device on a surface given as a formula, through the library API
//! instead of a spec file, and print what was measured.
//!
//! `cargo run --release --example formula_surface`

use moirecast_kernel::surface::FormulaSurface;
use moirecast_kernel::*;

fn main() -> anyhow::Result<()> {
    let surface = PitchSurface::Formula(
        FormulaSurface::parse("2*sin(x/8)*cos(y/10)").map_err(anyhow::Error::msg)?,
    );
    let mut params = DesignParams::with_defaults(surface, 20.0, 12.0, 0.5);
    params.profile = Profile::Rings { wavelength: 5.0 };
    let design = Design::new(params).map_err(|e| anyhow::anyhow!("{e}"))?;
    let build = moirecast::build_device(&design, &progress::Silent)?;
    let (checks, solid) = build.validated();
    let s = &build.mesh.stats;
    println!(
        "{} lenses, {} triangles ({} for a uniform grid)",
        design.lenses, s.triangles, s.uniform_triangles
    );
    println!(
        "measured AFOV {:.9}°–{:.9}°, pitch {:.4}–{:.4} mm",
        build.lens_stats.afov_deg.min,
        build.lens_stats.afov_deg.max,
        build.lens_stats.pitch.min,
        build.lens_stats.pitch.max
    );
    println!(
        "volume {:.3} mm³, solid: {}",
        build.mesh.mesh.volume(),
        solid.is_some()
    );
    for c in &checks {
        println!(
            "  {:<26} {:>12.3e} {:<9} (limit {:.1e}) {}",
            c.name,
            c.value,
            c.unit,
            c.limit,
            if c.passed { "ok" } else { "FAILED" }
        );
    }
    Ok(())
}
