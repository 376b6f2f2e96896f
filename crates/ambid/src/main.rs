fn main() {
    println!("ambid: under construction");
}
