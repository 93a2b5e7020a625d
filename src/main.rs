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
    #[cfg(unix)]
    interrupts();
    let args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    let cli = match lodtrace::cli::Cli::try_parse_from(join_negative_values(args.clone())) {
        Ok(c) => c,
        Err(e) => match e.kind() {
            ErrorKind::InvalidUtf8 => {
                // Scene, mesh and sequence arguments are text (built-in names or file names):
                // clap's "invalid UTF-8 was detected in one or more arguments" named neither
                // the argument nor what to do. Output paths take any name.
                let bad = args.iter().skip(1).find(|a| a.to_str().is_none()).map(|a| format!("{a:?}")).unwrap_or_default();
                lodtrace::status!(
                    "lodtrace: error: argument {}: not valid UTF-8; a scene, mesh or sequence file name (or an option's text) must be UTF-8: rename the file or link it under a UTF-8 name",
                    lodtrace::error::one_line(&bad)
                );
                std::process::exit(2);
            }
            ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
                // `e.exit()` ignores a failed write (`--help > /dev/full` exited 0).
                use std::io::Write as _;
                match e.print().and_then(|_| std::io::stdout().flush()) {
                    Ok(()) => std::process::exit(0),
                    Err(err) if err.kind() == std::io::ErrorKind::BrokenPipe => std::process::exit(0),
                    Err(err) => {
                        lodtrace::status!("lodtrace: error: <stdout>: {err}");
                        std::process::exit(2);
                    }
                }
            }
            ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
                // No subcommand: one line naming them, not the whole help on stderr.
                let cmd = <lodtrace::cli::Cli as clap::CommandFactory>::command();
                let subs: Vec<&str> = cmd.get_subcommands().map(|c| c.get_name()).filter(|n| *n != "help").collect();
                lodtrace::status!("lodtrace: error: give a subcommand ({}); `lodtrace --help` describes them", subs.join(", "));
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
                lodtrace::status!("lodtrace: error: {}", lodtrace::error::one_line(msg.trim_start_matches("error: ")));
                std::process::exit(2);
            }
        },
    };
    std::process::exit(lodtrace::cli::run(cli));
}

/// `--opt -1e-3` as `--opt=-1e-3`: clap takes a value starting with '-' for an option only
/// when it looks like a plain number, so `-1e-3`, `-.5`, `-inf` and `-1,0,1,1` were reported
/// as unknown arguments ('-1') instead of reaching the option's own range check. A value is
/// joined to the long option before it when that option takes a value and every
/// comma-separated piece of the value parses as a number.
fn join_negative_values(args: Vec<std::ffi::OsString>) -> Vec<std::ffi::OsString> {
    let cmd = <lodtrace::cli::Cli as clap::CommandFactory>::command();
    let sub = args.iter().skip(1).filter_map(|a| a.to_str()).find(|a| !a.starts_with('-')).and_then(|n| cmd.find_subcommand(n));
    let takes_value = |long: &str| {
        let find = |c: &clap::Command| c.get_arguments().find(|a| a.get_long() == Some(long)).map(|a| a.get_action().takes_values());
        sub.and_then(find).or_else(|| find(&cmd)).unwrap_or(false)
    };
    let numeric = |v: &str| v.starts_with('-') && v.split(',').all(|p| p.trim().parse::<f64>().is_ok());
    let mut out = Vec::with_capacity(args.len());
    let mut it = args.into_iter().peekable();
    let mut options = true;
    while let Some(a) = it.next() {
        options &= a != "--";
        let joined = match (a.to_str(), it.peek().and_then(|v| v.to_str())) {
            (Some(o), Some(v))
                if options && o.len() > 2 && o.starts_with("--") && !o.contains('=') && numeric(v) && takes_value(&o[2..]) =>
            {
                Some(format!("{o}={v}"))
            }
            _ => None,
        };
        match joined {
            Some(j) => {
                it.next();
                out.push(j.into());
            }
            None => out.push(a),
        }
    }
    out
}

/// Ctrl-C and SIGTERM end a run as a failed run ends: its outputs and the folders it created
/// are removed ([`lodtrace::film::io::remove_outputs_of_interrupted_run`]), one line says so,
/// and the exit code is 128 + the signal. The signals are blocked here, before any other
/// thread exists (threads inherit the mask), and taken by one thread with `sigwait`, so the
/// clean-up runs as ordinary code, not in a signal handler.
#[cfg(unix)]
fn interrupts() {
    // SAFETY: plain libc calls on a local signal set, before any other thread starts.
    let set = unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        libc::sigaddset(&mut set, libc::SIGINT);
        libc::sigaddset(&mut set, libc::SIGTERM);
        if libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut()) != 0 {
            return;
        }
        set
    };
    std::thread::spawn(move || {
        let mut sig: libc::c_int = 0;
        // SAFETY: `set` is an initialised signal set; `sig` receives the signal number.
        if unsafe { libc::sigwait(&set, &mut sig) } != 0 {
            return;
        }
        let n = lodtrace::film::io::remove_outputs_of_interrupted_run();
        let what = if sig == libc::SIGINT { "interrupted" } else { "terminated" };
        // A new line first only on a terminal, where a progress bar may be mid-line; a log
        // file gets the one error line and nothing else.
        use std::io::IsTerminal;
        let nl = if std::io::stderr().is_terminal() { "\n" } else { "" };
        if n > 0 {
            lodtrace::status!("{nl}lodtrace: error: {what}; removed the {n} outputs this run had written");
        } else {
            lodtrace::status!("{nl}lodtrace: error: {what}");
        }
        std::process::exit(128 + sig);
    });
}
