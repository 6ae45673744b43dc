//! The simulated images shown side by side (D, E, M, M⊙D, S, Y; paper IV.A and V.A), their colour ranges (automatic
//! or fixed), and their egui textures with the core's JET colour map. Display only: metres become millimetres here.

use egui::{Color32, TextureHandle, TextureOptions};
use tactile_derender::image::Image;
use tactile_derender::io::preview::{self, PanelStyle};
use tactile_derender::sim::SimOutput;

use crate::colormap::to_color_image;
use crate::state::{RangeMode, ViewState};

/// One of the simulator's images.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageKind {
    Depth,
    Elastomer,
    Mask,
    Target,
    Signature,
    Imprint,
}

impl ImageKind {
    /// The images in display order.
    pub const ALL: [ImageKind; 6] = [
        Self::Depth,
        Self::Elastomer,
        Self::Mask,
        Self::Target,
        Self::Signature,
        Self::Imprint,
    ];

    pub fn title(self) -> &'static str {
        match self {
            Self::Depth => "D object depth",
            Self::Elastomer => "E elastomer",
            Self::Mask => "M contact mask",
            Self::Target => "X0 = M·D contact depth",
            Self::Signature => "S signature",
            Self::Imprint => "Y imprint",
        }
    }

    /// File name without extension, as `tnd sim` writes it.
    pub fn file_stem(self) -> &'static str {
        match self {
            Self::Depth => "depth",
            Self::Elastomer => "elastomer",
            Self::Mask => "mask",
            Self::Target => "target",
            Self::Signature => "signature",
            Self::Imprint => "imprint",
        }
    }

    pub fn image(self, out: &SimOutput) -> &Image {
        match self {
            Self::Depth => &out.depth,
            Self::Elastomer => &out.elastomer,
            Self::Mask => &out.mask,
            Self::Target => &out.target,
            Self::Signature => &out.signature,
            Self::Imprint => &out.imprint,
        }
    }

    /// Zero means "no value" (depth images); masks and imprints use zero as a value.
    pub fn zero_is_missing(self) -> bool {
        !matches!(self, Self::Mask | Self::Imprint)
    }

    /// Values are lengths shown in mm (false for the 0/1 mask).
    pub fn millimetres(self) -> bool {
        self != Self::Mask
    }
}

/// Colour range (metres, or 0..1 for the mask) of `img` under the view settings.
pub fn range_for(kind: ImageKind, img: &Image, view: &ViewState) -> (f32, f32) {
    if kind == ImageKind::Mask {
        return (0.0, 1.0);
    }
    let fixed = match (view.range, kind) {
        (RangeMode::Auto, _) => None,
        (RangeMode::Fixed, ImageKind::Imprint) => Some(view.imprint_range),
        (RangeMode::Fixed, _) => Some(view.depth_range),
    };
    let style = PanelStyle {
        range_m: fixed,
        zero_is_missing: kind.zero_is_missing(),
        ..Default::default()
    };
    preview::display_range(img, &style)
}

/// A displayed image: its texture and colour range.
pub struct ShownImage {
    pub kind: ImageKind,
    pub texture: TextureHandle,
    pub range: (f32, f32),
}

/// What the textures were made from: simulation generation, range mode, fixed depth and imprint ranges.
type TextureKey = (u64, RangeMode, (f32, f32), (f32, f32));

/// Textures of the current simulation, rebuilt when the result or the colour ranges change.
#[derive(Default)]
pub struct ImageTextures {
    pub shown: Vec<ShownImage>,
    key: Option<TextureKey>,
}

impl ImageTextures {
    /// Make sure the textures show `out` (simulation `generation`) under `view`.
    pub fn update(
        &mut self,
        ctx: &egui::Context,
        generation: u64,
        out: &SimOutput,
        view: &ViewState,
    ) {
        let key = Some((generation, view.range, view.depth_range, view.imprint_range));
        if self.key == key {
            return;
        }
        self.key = key;
        self.shown = ImageKind::ALL
            .iter()
            .map(|&kind| {
                let img = kind.image(out);
                let range = range_for(kind, img, view);
                let texture = ctx.load_texture(
                    kind.file_stem(),
                    to_color_image(img, range, kind.zero_is_missing()),
                    TextureOptions::NEAREST,
                );
                ShownImage {
                    kind,
                    texture,
                    range,
                }
            })
            .collect();
    }
}

/// JET colour of `t` in [0, 1] as an egui colour.
pub fn jet_color(t: f32) -> Color32 {
    let [r, g, b] = preview::jet(t);
    Color32::from_rgb(r, g, b)
}

/// Format a value of `kind` for display: millimetres with one decimal, or the raw mask value.
pub fn format_value(kind: ImageKind, v: f32) -> String {
    if kind.millimetres() {
        format!("{:.1} mm", v * 1e3)
    } else {
        format!("{v:.1}")
    }
}
