//! Surrogate steps per second (the same call as `ocm surrogate bench`), batched over environments.
//! `cargo run --release -p ocm-surrogate --example bench -- MODEL.json [batch|batch-contact|rapier] [ENVS] [STEPS] [THREADS]`
use ocm_surrogate::bench::{BenchConfig, Engine, run};
use ocm_surrogate::model::SurrogateModel;
fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let m = SurrogateModel::read(std::path::Path::new(&a[0])).expect("model");
    let arg = |k: usize, d: usize| a.get(k).map(|s| s.parse().expect("number")).unwrap_or(d);
    let engine = Engine::parse(a.get(1).map_or("batch", String::as_str)).expect("engine");
    let cfg = BenchConfig {
        engine,
        envs: arg(2, 64),
        steps: arg(3, 500),
        threads: arg(4, 2),
        repeats: 5,
        seed: 1,
    };
    let r = run(&m.geometry.chain, &m.limits, &cfg).expect("bench");
    println!("{}", serde_json::to_string_pretty(&r).unwrap());
}
