//! The physical size of a pixel, taken from the input where its file states it (an Aperio
//! slide's MPP, OME-XML's PhysicalSizeX/Y, TIFF resolution tags in pixels per centimetre) and
//! recorded by the outputs that hold one: an OME-TIFF's OME-XML, an OME-Zarr's scale and a
//! DICOM series' Pixel Spacing (read again when a DICOM series is the input), each read back by its own world's reader (tifffile, zarr,
//! pydicom through the Python named by VORTEX_PYVIPS). `--pixel-size` overrides the file's.

use std::path::Path;

use crate::common::cli::{fails_with, ok, run, s};

/// Reads back what each output says a level-0 pixel measures, in micrometres, as a JSON
/// object: `ome` (OME-XML PhysicalSizeX/Y), `zarr` (level 0's and 1's scale, y and x),
/// `dicom` (level 0's and the next instance's Pixel Spacing, row and column).
const READ_BACK: &str = r#"
import sys, json, glob, os, tifffile, zarr, pydicom
import xml.etree.ElementTree as ET
said = {}
for arg in sys.argv[1:]:
    kind, path = arg.split("=", 1)
    if kind == "ome":
        pixels = ET.fromstring(tifffile.TiffFile(path).ome_metadata).find(".//{*}Pixels")
        said["ome"] = [float(pixels.get("PhysicalSizeX")), float(pixels.get("PhysicalSizeY")), pixels.get("PhysicalSizeXUnit")]
    elif kind == "zarr":
        attrs = dict(zarr.open_group(path, mode="r").attrs)
        ms = attrs.get("ome", attrs)["multiscales"][0]
        said["zarr"] = [d["coordinateTransformations"][0]["scale"][-2:] for d in ms["datasets"][:2]]
    elif kind == "dicom":
        spacing = []
        for f in sorted(glob.glob(os.path.join(path, "level-*.dcm")))[:2]:
            ds = pydicom.dcmread(f, stop_before_pixels=True)
            spacing.append([float(v) * 1000 for v in ds.SharedFunctionalGroupsSequence[0].PixelMeasuresSequence[0].PixelSpacing])
        said["dicom"] = spacing
print(json.dumps(said))
"#;

fn python() -> Option<std::path::PathBuf> {
    crate::common::python_with("tifffile, zarr, pydicom, numpy", "the pixel size readers", "tifffile, zarr and pydicom")
}

fn read_back(python: &Path, what: &[String]) -> serde_json::Value {
    let out = std::process::Command::new(python).arg("-c").arg(READ_BACK).args(what).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_str(String::from_utf8_lossy(&out.stdout).trim()).unwrap()
}

fn close(a: &serde_json::Value, b: f64) -> bool {
    // Decimal strings of a few digits (DICOM's DS, OME-XML) round-trip to within 1e-9.
    a.as_f64().is_some_and(|a| (a - b).abs() < 1e-9 * b)
}

/// An Aperio slide's MPP (0.5) goes into an OME-TIFF, an OME-Zarr and a DICOM series written
/// without --pixel-size; each reduced level measures its downsample times more (2x in our
/// pyramids, 4x in the slide's own level the DICOM series copies); --pixel-size wins.
#[test]
fn a_slide_s_mpp_is_recorded_by_every_output_that_holds_one() {
    let Some(python) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("slide.svs");
    crate::tiff_slides::python(python.as_os_str(), crate::tiff_slides::MAKE_SVS, &[s(&svs)]);
    let (ome, zarr, series) = (dir.path().join("a.ome.tif"), dir.path().join("a.ome.zarr"), dir.path().join("d"));
    ok(&["split", s(&svs), "-o", s(&ome), "-o", s(&zarr), "-q"]);
    let said = ok(&["split", s(&svs), "--layout", "dicom", "-o", s(&series)]);
    assert!(said.contains("0.5000 µm/texel (the Aperio description's MPP)"), "the summary says where: {said}");
    let said = read_back(
        &python,
        &[format!("ome={}", s(&ome)), format!("zarr={}", s(&zarr)), format!("dicom={}", s(&series))],
    );
    let ome = &said["ome"];
    assert!(close(&ome[0], 0.5) && close(&ome[1], 0.5) && ome[2] == "µm", "{said}");
    let zarr = &said["zarr"];
    assert!(close(&zarr[0][0], 0.5) && close(&zarr[0][1], 0.5) && close(&zarr[1][1], 1.0), "{said}");
    // The DICOM series copies the slide's own levels: its next is a quarter of the size.
    let dicom = &said["dicom"];
    assert!(close(&dicom[0][0], 0.5) && close(&dicom[0][1], 0.5) && close(&dicom[1][1], 2.0), "{said}");

    // Read back from the DICOM series, its Pixel Spacing is the input's pixel size again.
    let again = dir.path().join("again.ome.zarr");
    ok(&["split", s(&series), "-o", s(&again), "-q"]);
    let said = read_back(&python, &[format!("zarr={}", s(&again))]);
    assert!(close(&said["zarr"][0][0], 0.5) && close(&said["zarr"][0][1], 0.5), "from DICOM: {said}");

    let given = dir.path().join("given.ome.zarr");
    ok(&["split", s(&svs), "-o", s(&given), "--pixel-size", "0.25um", "-q"]);
    let said = read_back(&python, &[format!("zarr={}", s(&given))]);
    assert!(close(&said["zarr"][0][0], 0.25), "--pixel-size overrides the file's: {said}");
}

/// Resolution tags count in centimetres (20000 pixels per cm: 0.5 µm) or, for an OME-TIFF,
/// its PhysicalSizeX/Y in nanometres; a resolution in inches (a print size) is not a pixel
/// size, so a DICOM series then asks for --pixel-size.
#[test]
fn resolution_tags_in_centimetres_and_ome_xml_units_are_read() {
    let Some(python) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (cm, inch, ome) = (dir.path().join("cm.tif"), dir.path().join("inch.tif"), dir.path().join("in.ome.tif"));
    let make = r#"
import sys, numpy as np, tifffile
img = (np.arange(300 * 200 * 3) % 251).astype(np.uint8).reshape(200, 300, 3)
tifffile.imwrite(sys.argv[1], img, resolution=(20000, 20000), resolutionunit="CENTIMETER")
tifffile.imwrite(sys.argv[2], img, resolution=(300, 300), resolutionunit="INCH")
tifffile.imwrite(sys.argv[3], img, photometric="rgb", metadata={"PhysicalSizeX": 325, "PhysicalSizeXUnit": "nm", "PhysicalSizeY": 325, "PhysicalSizeYUnit": "nm"})
"#;
    crate::tiff_slides::python(python.as_os_str(), make, &[s(&cm), s(&inch), s(&ome)]);
    let (a, b) = (dir.path().join("cm.ome.zarr"), dir.path().join("ome.ome.zarr"));
    ok(&["split", s(&cm), "-o", s(&a), "-q"]);
    ok(&["split", s(&ome), "-o", s(&b), "-q"]);
    let said = read_back(&python, &[format!("zarr={}", s(&a))]);
    assert!(close(&said["zarr"][0][0], 0.5), "{said}");
    let said = read_back(&python, &[format!("zarr={}", s(&b))]);
    assert!(close(&said["zarr"][0][0], 0.325) && close(&said["zarr"][0][1], 0.325), "{said}");
    let d = dir.path().join("d");
    fails_with(
        &run(&["split", s(&inch), "--layout", "dicom", "-o", s(&d)]),
        &["the input states no square pixel size"],
    );
}
