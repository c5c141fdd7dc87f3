//! The few declarations of libjxl's C API (0.7, `jxl/encode.h`, `jxl/decode.h`) this crate
//! calls, written by hand from those headers: the structs' fields in the headers' order, the
//! enums as the `int`s C passes them as. Nothing here is public; `encode` and `decode` wrap
//! each call.

#![expect(unsafe_code, reason = "libjxl's C interface")]

use std::ffi::{c_double, c_float, c_int, c_void};

/// `JXL_BOOL`.
pub type JxlBool = c_int;
pub const JXL_TRUE: JxlBool = 1;
pub const JXL_FALSE: JxlBool = 0;

/// `JxlEncoder`, `JxlEncoderFrameSettings`, `JxlDecoder`: opaque.
#[repr(C)]
pub struct JxlEncoder {
    _opaque: [u8; 0],
}
#[repr(C)]
pub struct JxlEncoderFrameSettings {
    _opaque: [u8; 0],
}
#[repr(C)]
pub struct JxlDecoder {
    _opaque: [u8; 0],
}

/// `JxlEncoderStatus`.
pub const JXL_ENC_SUCCESS: c_int = 0;
pub const JXL_ENC_NEED_MORE_OUTPUT: c_int = 2;

/// `JxlEncoderFrameSettingId`: `JXL_ENC_FRAME_SETTING_EFFORT`.
pub const JXL_ENC_FRAME_SETTING_EFFORT: c_int = 0;

/// `JxlDecoderStatus`: the results and the events subscribed to.
pub const JXL_DEC_SUCCESS: c_int = 0;
pub const JXL_DEC_ERROR: c_int = 1;
pub const JXL_DEC_NEED_MORE_INPUT: c_int = 2;
pub const JXL_DEC_NEED_IMAGE_OUT_BUFFER: c_int = 5;
pub const JXL_DEC_BASIC_INFO: c_int = 0x40;
pub const JXL_DEC_FULL_IMAGE: c_int = 0x1000;

/// `JxlDataType`.
pub const JXL_TYPE_UINT8: c_int = 2;
pub const JXL_TYPE_UINT16: c_int = 3;
/// `JxlEndianness`: `JXL_NATIVE_ENDIAN`.
pub const JXL_NATIVE_ENDIAN: c_int = 0;

/// `JxlPixelFormat`: interleaved samples, rows packed (`align` 0).
#[repr(C)]
pub struct JxlPixelFormat {
    pub num_channels: u32,
    pub data_type: c_int,
    pub endianness: c_int,
    pub align: usize,
}

#[repr(C)]
#[derive(Default)]
pub struct JxlPreviewHeader {
    pub xsize: u32,
    pub ysize: u32,
}

#[repr(C)]
#[derive(Default)]
pub struct JxlAnimationHeader {
    pub tps_numerator: u32,
    pub tps_denominator: u32,
    pub num_loops: u32,
    pub have_timecodes: JxlBool,
}

/// `JxlBasicInfo` of libjxl 0.7 (its trailing padding reserves room for later fields).
#[repr(C)]
pub struct JxlBasicInfo {
    pub have_container: JxlBool,
    pub xsize: u32,
    pub ysize: u32,
    pub bits_per_sample: u32,
    pub exponent_bits_per_sample: u32,
    pub intensity_target: c_float,
    pub min_nits: c_float,
    pub relative_to_max_display: JxlBool,
    pub linear_below: c_float,
    pub uses_original_profile: JxlBool,
    pub have_preview: JxlBool,
    pub have_animation: JxlBool,
    pub orientation: c_int,
    pub num_color_channels: u32,
    pub num_extra_channels: u32,
    pub alpha_bits: u32,
    pub alpha_exponent_bits: u32,
    pub alpha_premultiplied: JxlBool,
    pub preview: JxlPreviewHeader,
    pub animation: JxlAnimationHeader,
    pub intrinsic_xsize: u32,
    pub intrinsic_ysize: u32,
    pub padding: [u8; 100],
}

impl JxlBasicInfo {
    /// All zero: what `JxlEncoderInitBasicInfo` then fills, or `JxlDecoderGetBasicInfo` overwrites.
    pub fn zeroed() -> JxlBasicInfo {
        JxlBasicInfo {
            have_container: 0,
            xsize: 0,
            ysize: 0,
            bits_per_sample: 0,
            exponent_bits_per_sample: 0,
            intensity_target: 0.0,
            min_nits: 0.0,
            relative_to_max_display: 0,
            linear_below: 0.0,
            uses_original_profile: 0,
            have_preview: 0,
            have_animation: 0,
            orientation: 0,
            num_color_channels: 0,
            num_extra_channels: 0,
            alpha_bits: 0,
            alpha_exponent_bits: 0,
            alpha_premultiplied: 0,
            preview: JxlPreviewHeader::default(),
            animation: JxlAnimationHeader::default(),
            intrinsic_xsize: 0,
            intrinsic_ysize: 0,
            padding: [0; 100],
        }
    }
}

/// `JxlColorEncoding`, filled by `JxlColorEncodingSetToSRGB`.
#[repr(C)]
#[derive(Default)]
pub struct JxlColorEncoding {
    pub color_space: c_int,
    pub white_point: c_int,
    pub white_point_xy: [c_double; 2],
    pub primaries: c_int,
    pub primaries_red_xy: [c_double; 2],
    pub primaries_green_xy: [c_double; 2],
    pub primaries_blue_xy: [c_double; 2],
    pub transfer_function: c_int,
    pub gamma: c_double,
    pub rendering_intent: c_int,
}

unsafe extern "C" {
    pub fn JxlEncoderCreate(memory_manager: *const c_void) -> *mut JxlEncoder;
    pub fn JxlEncoderDestroy(enc: *mut JxlEncoder);
    pub fn JxlEncoderGetError(enc: *mut JxlEncoder) -> c_int;
    pub fn JxlEncoderInitBasicInfo(info: *mut JxlBasicInfo);
    pub fn JxlEncoderSetBasicInfo(enc: *mut JxlEncoder, info: *const JxlBasicInfo) -> c_int;
    pub fn JxlColorEncodingSetToSRGB(color_encoding: *mut JxlColorEncoding, is_gray: JxlBool);
    pub fn JxlEncoderSetColorEncoding(enc: *mut JxlEncoder, color: *const JxlColorEncoding) -> c_int;
    pub fn JxlEncoderFrameSettingsCreate(
        enc: *mut JxlEncoder,
        source: *const JxlEncoderFrameSettings,
    ) -> *mut JxlEncoderFrameSettings;
    pub fn JxlEncoderFrameSettingsSetOption(
        frame_settings: *mut JxlEncoderFrameSettings,
        option: c_int,
        value: i64,
    ) -> c_int;
    pub fn JxlEncoderSetFrameDistance(frame_settings: *mut JxlEncoderFrameSettings, distance: c_float) -> c_int;
    pub fn JxlEncoderSetFrameLossless(frame_settings: *mut JxlEncoderFrameSettings, lossless: JxlBool) -> c_int;
    pub fn JxlEncoderStoreJPEGMetadata(enc: *mut JxlEncoder, store_jpeg_metadata: JxlBool) -> c_int;
    pub fn JxlEncoderAddImageFrame(
        frame_settings: *const JxlEncoderFrameSettings,
        pixel_format: *const JxlPixelFormat,
        buffer: *const c_void,
        size: usize,
    ) -> c_int;
    pub fn JxlEncoderAddJPEGFrame(
        frame_settings: *const JxlEncoderFrameSettings,
        buffer: *const u8,
        size: usize,
    ) -> c_int;
    pub fn JxlEncoderCloseInput(enc: *mut JxlEncoder);
    pub fn JxlEncoderProcessOutput(enc: *mut JxlEncoder, next_out: *mut *mut u8, avail_out: *mut usize) -> c_int;

    pub fn JxlDecoderCreate(memory_manager: *const c_void) -> *mut JxlDecoder;
    pub fn JxlDecoderDestroy(dec: *mut JxlDecoder);
    pub fn JxlDecoderSubscribeEvents(dec: *mut JxlDecoder, events_wanted: c_int) -> c_int;
    pub fn JxlDecoderSetInput(dec: *mut JxlDecoder, data: *const u8, size: usize) -> c_int;
    pub fn JxlDecoderCloseInput(dec: *mut JxlDecoder);
    pub fn JxlDecoderProcessInput(dec: *mut JxlDecoder) -> c_int;
    pub fn JxlDecoderGetBasicInfo(dec: *const JxlDecoder, info: *mut JxlBasicInfo) -> c_int;
    pub fn JxlDecoderImageOutBufferSize(
        dec: *const JxlDecoder,
        format: *const JxlPixelFormat,
        size: *mut usize,
    ) -> c_int;
    pub fn JxlDecoderSetImageOutBuffer(
        dec: *mut JxlDecoder,
        format: *const JxlPixelFormat,
        buffer: *mut c_void,
        size: usize,
    ) -> c_int;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sizes the C compiler gives these structs on 64-bit Linux (`sizeof` with libjxl 0.7's
    /// headers): a field left out or misordered would change them.
    #[test]
    #[cfg(target_pointer_width = "64")]
    fn struct_sizes_match_the_headers() {
        assert_eq!(size_of::<JxlPixelFormat>(), 24);
        assert_eq!(size_of::<JxlBasicInfo>(), 204);
        assert_eq!(size_of::<JxlColorEncoding>(), 104);
    }
}
