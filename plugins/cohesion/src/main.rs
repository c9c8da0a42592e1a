//! The `engine` command with the Cohesion plugin term registered beside the standard
//! stages and terms: `cargo run --release -p cohesion -- plugins/cohesion/square.ron`.

fn main() -> std::process::ExitCode {
    let mut registry = sph_stages::standard_registry();
    cohesion::register(&mut registry);
    engine::main_with(registry)
}
