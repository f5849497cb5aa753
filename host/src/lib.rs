//! Host side of catmodel: log files, the plant simulator, replay, evaluation, identification.

pub mod logcsv;
pub mod sim;
