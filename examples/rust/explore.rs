use rkmpm::verification::*;
use rkmpm::{Integration, Shape, Transfer};
fn main() {
    let mms = AxisAlignedMms::default();
    let args: Vec<String> = std::env::args().collect();
    let t_end: f64 = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(0.015);
    let cfl: f64 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(0.3);
    let only: String = args.get(3).cloned().unwrap_or_default();
    let cells_list: Vec<usize> = args
        .get(4)
        .map(|s| s.split(',').map(|c| c.parse().unwrap()).collect())
        .unwrap_or(vec![8, 16, 32]);
    let configs: Vec<(&str, Shape, Integration, Transfer)> = vec![
        (
            "B2 APIC",
            Shape::BSpline2,
            Integration::MaterialPoint,
            Transfer::Apic,
        ),
        (
            "B3 APIC",
            Shape::BSpline3,
            Integration::MaterialPoint,
            Transfer::Apic,
        ),
        (
            "RK1 VC1 APIC",
            Shape::Rk {
                order: 1,
                support: 2.0,
            },
            Integration::Vc { order: 1 },
            Transfer::Apic,
        ),
        (
            "RK2 PIC",
            Shape::Rk {
                order: 2,
                support: 3.0,
            },
            Integration::MaterialPoint,
            Transfer::PicFlip { flip: 0.0 },
        ),
        (
            "RK2 VC2 PIC",
            Shape::Rk {
                order: 2,
                support: 3.0,
            },
            Integration::Vc { order: 2 },
            Transfer::PicFlip { flip: 0.0 },
        ),
        (
            "RK2 VC2 FLIP",
            Shape::Rk {
                order: 2,
                support: 3.0,
            },
            Integration::Vc { order: 2 },
            Transfer::PicFlip { flip: 1.0 },
        ),
    ];
    for (name, shape, integ, tr) in configs {
        if !only.is_empty() && name != only {
            continue;
        }
        let mut hs = vec![];
        let mut l2 = vec![];
        let mut en = vec![];
        for &cells in &cells_list {
            match run_mms::<2>(&mms, cells, shape, integ, tr, t_end, cfl) {
                Ok(r) => {
                    hs.push(1.0 / cells as f64);
                    l2.push(r.errors.l2);
                    en.push(r.errors.energy);
                    println!(
                        "{name} {cells}: l2 {:.3e} energy {:.3e} ({:.2}s)",
                        r.errors.l2, r.errors.energy, r.seconds
                    );
                }
                Err(e) => {
                    println!("{name} {cells}: {e}");
                }
            }
        }
        if hs.len() >= 2 {
            println!(
                "{name}: slopes l2 {:.2} energy {:.2}",
                fitted_slope(&hs, &l2),
                fitted_slope(&hs, &en)
            );
        }
    }
}
