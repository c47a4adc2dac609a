//! `geofit completions SHELL` and `geofit man [COMMAND]`: shell completions (clap_complete) and
//! man pages (clap_mangen) generated from the CLI definition itself, so they never drift from
//! the options the binary accepts.

use clap::Args as ClapArgs;

use crate::config::Output;
use crate::error::{CliError, CmdResult, Exit};

const COMPLETIONS_EXAMPLE: &str = "\
Example:
  $ geofit completions bash > ~/.local/share/bash-completion/completions/geofit
  $ geofit completions zsh > ~/.zfunc/_geofit        # with fpath+=~/.zfunc in ~/.zshrc
  $ geofit completions fish > ~/.config/fish/completions/geofit.fish";

const MAN_EXAMPLE: &str = "\
Example:
  $ geofit man | man -l -                    # read geofit(1)
  $ geofit man fit -o geofit-fit.1           # the page of one subcommand
  $ for c in '' fit eval rasterize; do geofit man $c -o geofit${c:+-$c}.1; done";

#[derive(ClapArgs, Debug)]
#[command(about = "Print shell completions (bash, zsh, fish, elvish, powershell) for geofit", after_help = COMPLETIONS_EXAMPLE)]
pub struct Args {
    /// The shell to complete for.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

#[derive(ClapArgs, Debug)]
#[command(about = "Print geofit's man page (roff), or one subcommand's", after_help = MAN_EXAMPLE)]
pub struct ManArgs {
    /// The subcommand whose page to print (geofit-COMMAND(1)); none = geofit(1).
    pub command: Option<String>,
    /// Write the page to this file instead of stdout.
    #[arg(short, long)]
    pub output: Option<String>,
}

/// Writes the completion script for `args.shell` of `cli` to stdout.
pub fn run(args: Args, mut cli: clap::Command) -> CmdResult {
    Output::Stdout.write_with(|w| {
        clap_complete::generate(args.shell, &mut cli, "geofit", w);
        Ok(())
    })?;
    Ok(Exit::Ok)
}

/// Writes the man page of `cli` (or of one of its subcommands) to `-o` or stdout.
pub fn run_man(args: ManArgs, cli: clap::Command) -> CmdResult {
    let out = Output::from_arg(args.output.as_deref());
    out.check_target()?;
    let page = match &args.command {
        None => cli,
        Some(name) => {
            let names: Vec<String> = cli.get_subcommands().map(|c| c.get_name().to_string()).collect();
            let sub = cli.find_subcommand(name).cloned().ok_or_else(|| {
                CliError::usage(format!("geofit has no subcommand '{name}'; it has: {}", names.join(", ")))
            })?;
            // geofit-fit(1), with the version of the whole program
            sub.name(format!("geofit-{name}")).version(env!("CARGO_PKG_VERSION"))
        }
    };
    out.write_with(|w| clap_mangen::Man::new(page).render(w).map_err(CliError::io_out))?;
    Ok(Exit::Ok)
}
