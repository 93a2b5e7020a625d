use clap::error::ErrorKind;
use clap::Parser;

fn main() {
    let cli = match lodtrace::cli::Cli::try_parse() {
        Ok(c) => c,
        Err(e) => match e.kind() {
            ErrorKind::DisplayHelp | ErrorKind::DisplayVersion | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => e.exit(),
            _ => {
                // One clear line (clap's own message spans several).
                let text = e.render().to_string();
                let parts: Vec<&str> = text
                    .lines()
                    .map(str::trim)
                    .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more information"))
                    .filter(|l| !l.is_empty() && !l.starts_with("tip:"))
                    .collect();
                let msg = parts.join(" ");
                eprintln!("lodtrace: error: {}", msg.trim_start_matches("error: "));
                std::process::exit(2);
            }
        },
    };
    std::process::exit(lodtrace::cli::run(cli));
}
