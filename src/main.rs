use clap::error::ErrorKind;
use clap::Parser;

fn main() {
    // A file-size limit (`ulimit -f`) must fail the write (one error line, exit 2, temporary
    // files removed), not kill the process with SIGXFSZ and leave a partial file behind.
    #[cfg(unix)]
    // SAFETY: setting a signal's disposition to SIG_IGN before any thread starts.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
    let cli = match lodtrace::cli::Cli::try_parse() {
        Ok(c) => c,
        Err(e) => match e.kind() {
            ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => e.exit(),
            ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
                // No subcommand: one line naming them, not the whole help on stderr.
                let cmd = <lodtrace::cli::Cli as clap::CommandFactory>::command();
                let subs: Vec<&str> = cmd.get_subcommands().map(|c| c.get_name()).filter(|n| *n != "help").collect();
                eprintln!("lodtrace: error: give a subcommand ({}); `lodtrace --help` describes them", subs.join(", "));
                std::process::exit(2);
            }
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
