fn main() {
    for path in std::env::args().skip(1) {
        let spec = moirecast_spec::load(std::path::Path::new(&path)).unwrap();
        let d = &spec.design;
        let hh = d.half_height + d.margin.min(d.half_height);
        println!(
            "{path}: detail {:?} base cell {:.4}",
            d.params.profile.detail_mm(),
            2.0 * hh / 256.0
        );
    }
}
