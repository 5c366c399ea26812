//! Binary instance masks as the rest of chicktrain sees them: row-major, one byte per pixel.
//!
//! Images, renders and model outputs are row-major; only the RLE codec (`rle.rs`) walks
//! masks column-major, because that is the order pycocotools' run lengths are defined in.

/// A binary mask, `data[y * width + x]`, 0 = background, anything else = foreground.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mask {
    pub height: u32,
    pub width: u32,
    pub data: Vec<u8>,
}

impl Mask {
    /// An all-background mask.
    pub fn new(height: u32, width: u32) -> Mask {
        Mask {
            height,
            width,
            data: vec![0; height as usize * width as usize],
        }
    }

    /// Wraps row-major bytes; `None` when the length does not match the size.
    pub fn from_row_major(height: u32, width: u32, data: Vec<u8>) -> Option<Mask> {
        (data.len() == height as usize * width as usize).then_some(Mask {
            height,
            width,
            data,
        })
    }

    #[inline]
    pub fn get(&self, x: u32, y: u32) -> bool {
        self.data[y as usize * self.width as usize + x as usize] != 0
    }

    #[inline]
    pub fn set(&mut self, x: u32, y: u32, on: bool) {
        self.data[y as usize * self.width as usize + x as usize] = on as u8;
    }

    /// Number of foreground pixels.
    pub fn area(&self) -> u64 {
        self.data.iter().filter(|&&v| v != 0).count() as u64
    }

    /// Pixel-wise intersection over union of two masks of one size (0 when both are empty).
    pub fn iou(&self, other: &Mask) -> f64 {
        assert_eq!((self.height, self.width), (other.height, other.width));
        let (mut inter, mut union) = (0u64, 0u64);
        for (&a, &b) in self.data.iter().zip(&other.data) {
            let (a, b) = (a != 0, b != 0);
            inter += (a && b) as u64;
            union += (a || b) as u64;
        }
        if union == 0 {
            0.0
        } else {
            inter as f64 / union as f64
        }
    }
}

/// A mask of a `width × height` image that is background outside one window: what a
/// detection decodes to at the original image size. Decoding only inside the box keeps
/// validation from building hundreds of full-image masks per image; the RLE is built
/// from the window directly ([`crate::annotations::rle::Rle::encode_cropped`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CroppedMask {
    /// Size of the whole image.
    pub width: u32,
    pub height: u32,
    /// Top-left corner of the window in the image.
    pub x0: u32,
    pub y0: u32,
    /// The window's pixels; it must lie inside the image.
    pub window: Mask,
}

impl CroppedMask {
    /// An all-background mask of a `width × height` image.
    pub fn empty(width: u32, height: u32) -> CroppedMask {
        CroppedMask {
            width,
            height,
            x0: 0,
            y0: 0,
            window: Mask::new(0, 0),
        }
    }

    /// The whole-image mask.
    pub fn full(&self) -> Mask {
        let mut out = Mask::new(self.height, self.width);
        let (ww, wh) = (self.window.width as usize, self.window.height as usize);
        for y in 0..wh {
            let dst = (self.y0 as usize + y) * self.width as usize + self.x0 as usize;
            out.data[dst..dst + ww].copy_from_slice(&self.window.data[y * ww..(y + 1) * ww]);
        }
        out
    }

    pub fn area(&self) -> u64 {
        self.window.area()
    }
}

/// Resizes a mask with nearest-neighbour sampling (pixel centres).
pub fn resize_mask(m: &Mask, width: u32, height: u32) -> Mask {
    if m.width == width && m.height == height {
        return m.clone();
    }
    let mut out = Mask::new(height, width);
    for y in 0..height {
        let sy = (((y as f64 + 0.5) * m.height as f64 / height as f64) as u32).min(m.height - 1);
        for x in 0..width {
            let sx = (((x as f64 + 0.5) * m.width as f64 / width as f64) as u32).min(m.width - 1);
            out.data[(y * width + x) as usize] = m.data[(sy * m.width + sx) as usize];
        }
    }
    out
}
