//! cpm-kinematics (work in progress).
