//! Reads `u,y` rows (CSV with a header line) from stdin, writes `x,x_std,flags` rows: the
//! no_std library's [`hbn_firmware_rust::estimate`] run on a host, to compare with
//! `hbn estimate`.

use std::io::{BufRead, Write};

use hbn_firmware_rust::{Sample, WORK_LEN, estimate};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (mut u, mut y) = (Vec::new(), Vec::new());
    for (i, line) in std::io::stdin().lock().lines().enumerate() {
        let line = line?;
        if i == 0 || line.trim().is_empty() {
            continue;
        }
        let mut cols = line.split(',');
        let (Some(a), Some(b)) = (cols.next(), cols.next()) else {
            return Err(format!("line {} is not `u,y`: {line}", i + 1).into());
        };
        u.push(a.trim().parse::<f64>()?);
        y.push(b.trim().parse::<f64>()?);
    }
    let mut out = vec![Sample::default(); u.len()];
    let mut work = vec![0.0; WORK_LEN];
    let n = estimate(&u, &y, &mut out, &mut work).map_err(|e| format!("{e}"))?;
    let mut w = std::io::BufWriter::new(std::io::stdout().lock());
    writeln!(w, "x,x_std,flags")?;
    for s in out.iter().take(n) {
        // `{:?}` prints the shortest text that reads back to the same bits.
        writeln!(w, "{:?},{:?},{}", s.x, s.x_std, s.flags)?;
    }
    Ok(())
}
