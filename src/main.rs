use clap::Parser;

fn main() {
    let cli = lodtrace::cli::Cli::parse();
    std::process::exit(lodtrace::cli::run(cli));
}
