//! The real-time loop (being written).
