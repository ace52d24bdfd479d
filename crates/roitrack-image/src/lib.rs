//! Image side of roitrack (being written).
