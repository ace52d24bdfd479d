use roitrack_bench::HotPaths;
fn main() {
    let hot = HotPaths::new();
    let mode = std::env::args().nth(1).unwrap_or_default();
    if mode == "cg" {
        let n: usize = std::env::args().nth(2).unwrap().parse().unwrap();
        for _ in 0..n {
            std::hint::black_box(hot.centroid().unwrap());
        }
        return;
    }
    let mut best = [f64::INFINITY; 2];
    for _ in 0..200 {
        for (k, b) in best.iter_mut().enumerate() {
            let t = std::time::Instant::now();
            for _ in 0..2000 {
                if k == 0 {
                    std::hint::black_box(hot.centroid().unwrap());
                } else {
                    std::hint::black_box(hot.centroid_moments().unwrap());
                }
            }
            *b = b.min(t.elapsed().as_secs_f64() / 2000.0 * 1e6);
        }
    }
    println!("min us: centroid {:.4} moments {:.4}", best[0], best[1]);
}
