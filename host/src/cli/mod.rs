//! One module per `meb` subcommand: argument parsing and printing only.

pub mod carriers;
pub mod device;
pub mod simulate;
