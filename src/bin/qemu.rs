//! (in progress on branch fw)
#![no_std]
#![no_main]
