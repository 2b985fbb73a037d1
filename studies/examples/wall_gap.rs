//! How far above a floor a body comes to rest, per shape function and wall kind.
//!
//! ```text
//! cargo run --release --example wall_gap
//! ```
//!
//! A neo-Hookean block (8 × 4 cells, 2 × 2 particles per cell, ρ = 1000 kg/m³, E = 1 MPa,
//! ν = 0.3) under gravity on a 32 × 32 grid of cells of h = 1/32 m, the floor a wall on the
//! grid's lower face: once placed on the floor (its lower face on it) and once dropped from 2h
//! above it. PIC (which damps) for 1 s of simulated time, then the gap: the lowest particle's
//! height less the quarter cell its centre lies above the block's lower face, in cells. The
//! walls act on grid nodes, so a body feels the floor once its particles' support reaches the
//! floor's nodes; what it rests on is the velocity those nodes get.

use rkmpm::{Material, Shape, Side, Sim, Transfer, Wall};

type V = rkmpm::Vector<2>;

const CELLS: usize = 32;

/// The gap, in cells, of the block after 1 s, its lower face first at `start` cells.
fn gap(shape: Shape, wall: Wall, start: f64) -> Result<f64, String> {
    let h = 1.0 / CELLS as f64;
    let mut sim = Sim::<2>::new([0.0, 0.0], [CELLS, CELLS], h).map_err(|e| e.message)?;
    sim.set_shape(shape).map_err(|e| e.message)?;
    sim.set_transfer(Transfer::PicFlip { flip: 0.0 })
        .map_err(|e| e.message)?;
    sim.set_wall(1, Side::Low, wall).map_err(|e| e.message)?;
    sim.set_gravity(V::new(0.0, -9.81)).map_err(|e| e.message)?;
    let m = sim.add_material(Material::neo_hookean(1000.0, 1e6, 0.3).map_err(|e| e.message)?);
    let s = 0.5 * h;
    let x: Vec<V> = (0..16 * 8)
        .map(|k| {
            V::new(
                12.0 * h + s * (0.5 + (k % 16) as f64),
                start * h + s * (0.5 + (k / 16) as f64),
            )
        })
        .collect();
    sim.add_particles(m, &x, &vec![s * s; x.len()], None)
        .map_err(|e| e.message)?;
    while sim.time() < 1.0 {
        let dt = sim.stable_dt(0.3).map_err(|e| e.message)?;
        sim.step(dt.min(1.0 - sim.time()).max(1e-12))
            .map_err(|e| e.message)?;
    }
    let lowest = sim
        .particles()
        .position()
        .iter()
        .map(|p| p[1])
        .fold(f64::INFINITY, f64::min);
    Ok((lowest - 0.5 * s) / h)
}

fn main() {
    let shapes = [
        ("linear hats", Shape::Linear),
        ("quadratic B-spline", Shape::BSpline2),
        ("cubic B-spline", Shape::BSpline3),
        (
            "RK2 (ã = 3)",
            Shape::Rk {
                order: 2,
                support: 3.0,
            },
        ),
    ];
    println!("| shape | wall | placed on the floor | dropped from 2h |");
    println!("|---|---|---|---|");
    for (name, shape) in shapes {
        for (wall_name, wall) in [
            ("slip", Wall::Slip),
            ("fixed", Wall::Fixed),
            ("friction 0.3", Wall::Friction(0.3)),
        ] {
            // A run the engine stops (linear hats' cell crossing inverts particles) says when.
            let cell = |start: f64| match gap(shape, wall, start) {
                Ok(g) => format!("{g:.3}"),
                Err(e) => format!("stopped: {}", e.split(" rejected").next().unwrap_or(&e)),
            };
            println!("| {name} | {wall_name} | {} | {} |", cell(0.0), cell(2.0));
        }
    }
}
