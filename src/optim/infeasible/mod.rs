//! Proofs, before any solve, that a request cannot be met: the joint-space
//! certificates of [`diagnose`] and the closed-form duration bound of
//! [`duration`].

pub mod diagnose;
pub mod duration;
