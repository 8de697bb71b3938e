fn main() {
    lightfarm::main()
}
