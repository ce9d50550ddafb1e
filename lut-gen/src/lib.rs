//! ocm-lutgen (being written).
