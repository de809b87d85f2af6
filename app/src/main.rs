//! The `isoscope` binary: a thin shell over the app library.

fn main() {
    println!("isoscope");
}
