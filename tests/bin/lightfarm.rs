//! The `lightfarm` program built inside this package, so that its tests can run it as real
//! processes (Cargo gives a test the path of a binary only from its own package).

fn main() {
    lightfarm::main()
}
