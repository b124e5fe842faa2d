//! A small glTF model written by hand (positions and indices in a base64 data URI): a bumpy
//! square whose node 0 has an `MSFT_lod` chain. Used by the progressive-mesh tests and as the
//! glTF reader's seed in the fuzz tests.

/// Standard base64 (for a glTF data URI).
fn base64(bytes: &[u8]) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ABC[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// A bumpy square of `n` x `n` quads as (positions, u16 indices).
pub fn bumpy_square(n: usize) -> (Vec<[f32; 3]>, Vec<u16>) {
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
            let z = 0.2 * (x * 6.0).sin() * (y * 5.0).cos();
            pos.push([x, y, z]);
        }
    }
    let mut idx = Vec::new();
    let at = |i: usize, j: usize| (j * (n + 1) + i) as u16;
    for j in 0..n {
        for i in 0..n {
            idx.extend([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            idx.extend([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    (pos, idx)
}

/// A glTF whose node 0 (translated by +10 m in x) has an MSFT_lod chain of nodes 1 and 2 (the
/// last one collapsed to a point with `flat_last`).
pub fn gltf_with_chain(mode: u32, missing_lod: bool, flat_last: bool) -> String {
    let mut bin = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut meshes = Vec::new();
    for (m, n) in [16usize, 4, 1].into_iter().enumerate() {
        let (mut pos, idx) = bumpy_square(n);
        if flat_last && m == 2 {
            pos.fill([0.0; 3]);
        }
        let (p0, i0) = (bin.len(), {
            for p in &pos {
                for x in p {
                    bin.extend_from_slice(&x.to_le_bytes());
                }
            }
            bin.len()
        });
        for i in &idx {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        views.push(format!(
            r#"{{"buffer":0,"byteOffset":{p0},"byteLength":{}}}"#,
            i0 - p0
        ));
        views.push(format!(
            r#"{{"buffer":0,"byteOffset":{i0},"byteLength":{}}}"#,
            idx.len() * 2
        ));
        accessors.push(format!(
            r#"{{"bufferView":{},"componentType":5126,"count":{},"type":"VEC3","min":[0,0,-0.3],"max":[1,1,0.3]}}"#,
            2 * m,
            pos.len()
        ));
        accessors.push(format!(
            r#"{{"bufferView":{},"componentType":5123,"count":{},"type":"SCALAR"}}"#,
            2 * m + 1,
            idx.len()
        ));
        meshes.push(format!(
            r#"{{"primitives":[{{"attributes":{{"POSITION":{}}},"indices":{},"mode":{mode}}}]}}"#,
            2 * m,
            2 * m + 1
        ));
    }
    let lods = if missing_lod { "[1, 9]" } else { "[1, 2]" };
    format!(
        r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["MSFT_lod"],"scene":0,"scenes":[{{"nodes":[0]}}],
"nodes":[{{"mesh":0,"translation":[10,0,0],"extensions":{{"MSFT_lod":{{"ids":{lods}}}}}}},{{"mesh":1}},{{"mesh":2}}],
"meshes":[{}],"accessors":[{}],"bufferViews":[{}],
"buffers":[{{"byteLength":{},"uri":"data:application/octet-stream;base64,{}"}}]}}"#,
        meshes.join(","),
        accessors.join(","),
        views.join(","),
        bin.len(),
        base64(&bin)
    )
}
