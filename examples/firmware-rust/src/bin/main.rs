//! Reads `u,y` rows (CSV with a header line) from stdin, writes `x,x_std,flags` rows: the
//! no_std library's `estimate` run on a host, to compare with `hbn estimate`. With the `vector`
//! feature it reads the columns its header names `u0`, `u1`, ... and `y0`, `y1`, ... and writes
//! `x0,x0_std,x1,x1_std,...,flags` rows.

use std::io::{BufRead, Write};

#[cfg(not(feature = "vector"))]
use hbn_firmware_rust::{Sample, WORK_LEN, estimate};

#[cfg(feature = "vector")]
fn main() -> Result<(), Box<dyn std::error::Error>> {
    use hbn_firmware_rust::model::{HBN_INPUTS, HBN_SENSORS, HBN_STATES};
    use hbn_firmware_rust::vector::{Sample, estimate};
    let mut lines = std::io::stdin().lock().lines();
    let header = lines.next().ok_or("no header line")??;
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let col = |name: String| {
        names
            .iter()
            .position(|n| *n == name)
            .ok_or(format!("the header names no `{name}` column"))
    };
    let cu = (0..HBN_INPUTS)
        .map(|a| col(format!("u{a}")))
        .collect::<Result<Vec<_>, _>>()?;
    let cy = (0..HBN_SENSORS)
        .map(|j| col(format!("y{j}")))
        .collect::<Result<Vec<_>, _>>()?;
    let (mut u, mut y) = (Vec::new(), Vec::new());
    for line in lines {
        let line = line?;
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let get = |c: usize| -> Result<f64, Box<dyn std::error::Error>> {
            Ok(fields.get(c).ok_or("a short row")?.parse::<f64>()?)
        };
        for &c in &cu {
            u.push(get(c)?);
        }
        for &c in &cy {
            y.push(get(c)?);
        }
    }
    let mut out = vec![Sample::default(); u.len() / HBN_INPUTS];
    let mut work = vec![0.0; hbn_firmware_rust::WORK_LEN];
    let n = estimate(&u, &y, &mut out, &mut work).map_err(|e| format!("{e}"))?;
    let mut w = std::io::BufWriter::new(std::io::stdout().lock());
    for i in 0..HBN_STATES {
        write!(w, "x{i},x{i}_std,")?;
    }
    writeln!(w, "flags")?;
    for s in out.iter().take(n) {
        for i in 0..HBN_STATES {
            // `{:?}` prints the shortest text that reads back to the same bits.
            write!(w, "{:?},{:?},", s.x[i], s.x_std[i])?;
        }
        writeln!(w, "{}", s.flags)?;
    }
    Ok(())
}

#[cfg(not(feature = "vector"))]
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
