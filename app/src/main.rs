//! The `sculpt` program.

fn main() {
    println!("sculpt");
}
