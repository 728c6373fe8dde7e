//! The designed sensor sockets: four base and four platform sockets, all paired (16 gauges),
//! the layout of the paper reproduction's designed campaign, used by many examples and tests.
use cpm_geometry::Sensor;

/// Extra sensor sockets for the designed campaign: four base sockets around the machine and
/// four platform sockets, every base socket paired with every platform socket (16 sensors,
/// named `b{i}p{j}`). The paper's sockets are `b1` and `p1`.
pub fn designed_sensors() -> Vec<Sensor> {
    let base = [
        [-200.0, 500.0, 500.0],
        [350.0, -350.0, 450.0],
        [-400.0, -250.0, 250.0],
        [400.0, 300.0, 250.0],
    ];
    let platform = [
        [-200.0, 205.0, -5.0],
        [150.0, -150.0, 0.0],
        [-150.0, -150.0, -150.0],
        [150.0, 150.0, -250.0],
    ];
    let mut out = Vec::new();
    for (i, b) in base.iter().enumerate() {
        for (j, p) in platform.iter().enumerate() {
            out.push(Sensor::new(&format!("b{}p{}", i + 1, j + 1), *b, *p));
        }
    }
    out
}
