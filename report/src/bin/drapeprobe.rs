#[path = "../../../examples/drape/mod.rs"]
#[allow(dead_code)]
mod drape;
fn main() {
    for method in ["stiff", "chebyshev", "pd"] {
        for sc in [true, false] {
            let settings = drape::DrapeSettings {
                method: method.parse().unwrap(),
                n: 32,
                self_collision: sc,
                throw_at: None,
            };
            let r = drape::run_headless(settings, 600);
            let p = &r.penetrations;
            let sheets: Vec<String> = r
                .sheets
                .iter()
                .map(|(n, s, t)| {
                    format!(
                        "[{n} v, stretch {:.2} %, median {:.2} ms, {:?}]",
                        100.0 * s.max_stretch,
                        t.as_secs_f64() * 1e3,
                        s.status
                    )
                })
                .collect();
            println!(
                "{method} sc={sc}: total {} worst {} steps {} {}",
                p.total,
                p.worst,
                p.steps,
                sheets.join(" ")
            );
        }
    }
}
