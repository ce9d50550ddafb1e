//! ocm-firmware (being written).
