//! `cargo xtask apk [--release]`: the Quest 3 APK without the Android NDK or SDK
//! downloads, from Debian packages (the recipe established on these machines:
//! ../shared/notes/android-build.md): a stub sysroot generated from committed
//! sources (android/sysroot), the library cross-built for aarch64-linux-android
//! (API 29, panic=abort, 16 KiB pages, --no-undefined) and stripped, the OpenXR
//! loader added, resources linked by aapt2 against android-framework-res, assets
//! bundled, zipaligned, signed with a debug keystore made once, verified, and
//! checked (badging, permissions, the library's imports and exports).
//! `cargo xtask install` installs it on a connected headset (adb) and starts it.

use anyhow::{bail, ensure, Context, Result};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Debian packages the APK build needs, and a command each provides.
const PACKAGES: &[(&str, &str)] = &[
    ("clang-16", "clang-16"),
    ("lld-16", "ld.lld-16"),
    ("llvm-16", "llvm-strip-16"),
    ("aapt", "aapt2"),
    ("aapt", "aapt"),
    ("apksigner", "apksigner"),
    ("zipalign", "zipalign"),
    ("zip", "zip"),
];
const FRAMEWORK_RES: &str = "/usr/share/android-framework-res/framework-res.apk";
const API: u32 = 29;
const TARGET: &str = "aarch64-linux-android";
/// The OpenXR loader when the user supplies none: the Khronos loader built for
/// arm64-v8a inside PyPI's pyopenxr wheel (Apache-2.0), pinned by version and hash.
const PYOPENXR: &str = "pyopenxr==1.1.6501";
const LOADER_IN_WHEEL: &str = "xr/library/android_arm_v8a/libopenxr_loader.so";
const LOADER_SHA256: &str = "a16aa41bbee2c9cf313b57ce3eb2d316be3a8bdfde2460394acd1cab3d7d37de";
/// The only shared libraries the app may import (Android's stable NDK ABI).
const ALLOWED_NEEDED: &[&str] =
    &["libc.so", "libm.so", "libdl.so", "liblog.so", "libandroid.so", "libcamera2ndk.so", "libmediandk.so"];

fn have(cmd: &str) -> bool {
    Command::new("sh").args(["-c", &format!("command -v {cmd}")]).output().is_ok_and(|o| o.status.success())
}

fn run(cmd: &mut Command) -> Result<String> {
    let shown = format!("{cmd:?}");
    let out = cmd.output().with_context(|| format!("running {shown}"))?;
    if !out.status.success() {
        bail!("{shown} failed: {}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

fn check_tools() -> Result<()> {
    let mut missing: Vec<&str> = PACKAGES.iter().filter(|(_, c)| !have(c)).map(|(p, _)| *p).collect();
    if !Path::new(FRAMEWORK_RES).exists() {
        missing.push("android-framework-res");
    }
    missing.dedup();
    if !missing.is_empty() {
        bail!("the APK build needs these Debian packages: apt-get install {}", missing.join(" "));
    }
    ensure!(have("keytool"), "the APK build needs keytool (a JDK: apt-get install default-jdk-headless)");
    Ok(())
}

/// The stub sysroot: link-time-only libc/libm/libdl/liblog/libandroid defining the
/// symbols in android/sysroot/symbols.txt, and crtbegin_so.o / crtend_so.o /
/// an empty libunwind.a, compiled from the committed sources.
fn sysroot(root: &Path, out: &Path) -> Result<PathBuf> {
    let src = root.join("android/sysroot");
    let lib = out.join(format!("usr/lib/{TARGET}/{API}"));
    std::fs::create_dir_all(&lib).with_context(|| format!("creating {}", lib.display()))?;
    let target = format!("--target={TARGET}{API}");
    let obj = out.join("obj");
    std::fs::create_dir_all(&obj)?;
    let cc = |args: &[&str]| run(Command::new("clang-16").arg(&target).args(args));
    let p = |p: &Path| p.display().to_string();
    cc(&["-c", "-fPIC", "-O2", &p(&src.join("crtbegin_so.c")), "-o", &p(&obj.join("crtbegin.o"))])?;
    cc(&["-c", &format!("-D__ANDROID_API__={API}"), &p(&src.join("crtbrand.S")), "-o", &p(&obj.join("crtbrand.o"))])?;
    run(Command::new("ld.lld-16")
        .args(["-r", &p(&obj.join("crtbegin.o")), &p(&obj.join("crtbrand.o")), "-o"])
        .arg(lib.join("crtbegin_so.o")))?;
    cc(&["-c", &p(&src.join("crtend_so.c")), "-o", &p(&lib.join("crtend_so.o"))])?;
    cc(&["-c", &p(&src.join("empty.c")), "-o", &p(&obj.join("empty.o"))])?;
    let unwind = lib.join("libunwind.a");
    let _ = std::fs::remove_file(&unwind);
    run(Command::new("llvm-ar-16").arg("rcs").arg(&unwind).arg(obj.join("empty.o")))?;
    let symbols = std::fs::read_to_string(src.join("symbols.txt")).context("reading android/sysroot/symbols.txt")?;
    let mut groups: std::collections::BTreeMap<&str, Vec<&str>> =
        ["c", "m", "dl", "log", "android"].iter().map(|l| (*l, vec![])).collect();
    for s in symbols.lines().map(str::trim).filter(|s| !s.is_empty() && !s.starts_with('#')) {
        groups.entry(library_of(s)).or_default().push(s);
    }
    for (l, syms) in &groups {
        let c = obj.join(format!("lib{l}.stub.c"));
        let body: String = syms.iter().map(|s| format!("void {s}(void) {{}}\n")).collect();
        std::fs::write(&c, format!("/* generated by cargo xtask apk: link-time stub, never shipped */\n{body}"))?;
        cc(&[
            "-nostdlib",
            "-shared",
            "-fPIC",
            "-fuse-ld=lld",
            &format!("-Wl,-soname,lib{l}.so"),
            &p(&c),
            "-o",
            &p(&lib.join(format!("lib{l}.so"))),
        ])?;
    }
    Ok(out.to_path_buf())
}

/// Which Android library defines `symbol` (bionic's split of libc/libm/libdl; the
/// NDK's liblog, libandroid, camera and media libraries by prefix).
fn library_of(symbol: &str) -> &'static str {
    const LIBM: &str = "acos acosf acosh acoshf asin asinf asinh asinhf atan atanf atan2 atan2f atanh atanhf cbrt cbrtf ceil ceilf \
        copysign copysignf cos cosf cosh coshf erf erff erfc erfcf exp expf exp2 exp2f expm1 expm1f fabs fabsf fdim fdimf floor floorf \
        fma fmaf fmax fmaxf fmin fminf fmod fmodf frexp frexpf hypot hypotf ilogb ilogbf ldexp ldexpf lgamma lgammaf lgamma_r lgammaf_r \
        llrint llrintf llround llroundf log logf log10 log10f log1p log1pf log2 log2f logb logbf lrint lrintf lround lroundf modf modff \
        nan nanf nearbyint nearbyintf nextafter nextafterf pow powf remainder remainderf remquo remquof rint rintf round roundf scalbn \
        scalbnf sin sinf sincos sincosf sinh sinhf sqrt sqrtf tan tanf tanh tanhf tgamma tgammaf trunc truncf";
    const LIBDL: &[&str] =
        &["dlopen", "dlclose", "dlsym", "dlerror", "dladdr", "dlvsym", "dl_iterate_phdr", "android_dlopen_ext"];
    if symbol.starts_with("__android_log_") {
        "log"
    } else if symbol.starts_with("ACamera") || symbol.starts_with("ACapture") {
        "camera2ndk"
    } else if symbol.starts_with("AImage") || symbol.starts_with("AMedia") {
        "mediandk"
    } else if symbol.starts_with('A')
        && symbol.contains('_')
        && symbol[..symbol.find('_').unwrap_or(0)].chars().all(|c| c.is_ascii_alphanumeric())
    {
        "android"
    } else if LIBDL.contains(&symbol) {
        "dl"
    } else if LIBM.split_whitespace().any(|m| m == symbol) {
        "m"
    } else {
        "c"
    }
}

fn loader(work: &Path) -> Result<PathBuf> {
    if let Some(p) = std::env::var_os("OPENXR_LOADER_SO") {
        let p = PathBuf::from(p);
        ensure!(p.exists(), "OPENXR_LOADER_SO={} does not exist", p.display());
        eprintln!("OpenXR loader: {} (OPENXR_LOADER_SO)", p.display());
        return Ok(p);
    }
    let dir = work.join("pyopenxr");
    let so = dir.join("libopenxr_loader.so");
    if !so.exists() {
        std::fs::create_dir_all(&dir)?;
        eprintln!("OpenXR loader: downloading {PYOPENXR} from PyPI (set OPENXR_LOADER_SO to use your own)");
        run(Command::new("python3")
            .args(["-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:", PYOPENXR, "-d"])
            .arg(&dir))?;
        let script = format!(
            "import glob,sys,zipfile\nw=glob.glob(sys.argv[1]+'/pyopenxr-*.whl')[0]\nopen(sys.argv[2],'wb').write(zipfile.ZipFile(w).read('{LOADER_IN_WHEEL}'))"
        );
        run(Command::new("python3").args(["-c", &script]).arg(&dir).arg(&so))?;
    }
    let sha = run(Command::new("sha256sum").arg(&so))?;
    let sha = sha.split_whitespace().next().unwrap_or("");
    ensure!(sha == LOADER_SHA256, "{}: sha256 {sha}, expected {LOADER_SHA256} ({PYOPENXR})", so.display());
    eprintln!("OpenXR loader: {PYOPENXR} {LOADER_IN_WHEEL}, sha256 {sha}");
    Ok(so)
}

fn keystore() -> Result<PathBuf> {
    let home = std::env::var_os("HOME").map(PathBuf::from).unwrap_or_else(|| PathBuf::from("."));
    let ks = home.join(".android/debug.keystore");
    if !ks.exists() {
        std::fs::create_dir_all(ks.parent().unwrap_or(&home))?;
        eprintln!("creating the debug keystore {} (once)", ks.display());
        run(Command::new("keytool").args(["-genkeypair", "-keystore"]).arg(&ks).args([
            "-storepass",
            "android",
            "-alias",
            "androiddebugkey",
            "-keypass",
            "android",
            "-keyalg",
            "RSA",
            "-keysize",
            "2048",
            "-validity",
            "10000",
            "-dname",
            "CN=Android Debug,O=Android,C=US",
        ]))?;
    }
    Ok(ks)
}

/// Build, sign and check the APK; returns its path.
pub fn apk(root: &Path, release: bool) -> Result<PathBuf> {
    check_tools()?;
    let work = root.join("target/android");
    let sysroot = sysroot(root, &work.join("sysroot"))?;
    let profile = if release { "release" } else { "debug" };
    let mut cmd = Command::new(env!("CARGO"));
    cmd.current_dir(root)
        .args(["rustc", "--lib", "--crate-type", "cdylib", "--locked", "--target", TARGET])
        .args(["--config", &format!("profile.{}.panic=\"abort\"", if release { "release" } else { "dev" })])
        .env("ANDROID_STUB_SYSROOT", &sysroot)
        .env("CARGO_TARGET_AARCH64_LINUX_ANDROID_LINKER", root.join("android/android-clang.sh"))
        .env("CC_aarch64_linux_android", "clang-16")
        .env("AR_aarch64_linux_android", "llvm-ar-16")
        .env("CFLAGS_aarch64_linux_android", format!("--target={TARGET}{API}"));
    if release {
        cmd.arg("--release");
    }
    eprintln!("$ cargo rustc --lib --crate-type cdylib --target {TARGET} ({profile}, panic=abort)");
    let status = cmd.status().context("running cargo rustc")?;
    ensure!(status.success(), "cross-building the Android library failed");
    let built = root.join(format!("target/{TARGET}/{profile}/libblind_augment.so"));
    let stage = work.join("stage");
    let _ = std::fs::remove_dir_all(&stage);
    let libs = stage.join("lib/arm64-v8a");
    std::fs::create_dir_all(&libs)?;
    let lib = libs.join("libblind_augment.so");
    run(Command::new("llvm-strip-16").arg("--strip-unneeded").arg(&built).arg("-o").arg(&lib))?;
    std::fs::copy(loader(&work)?, libs.join("libopenxr_loader.so")).context("copying the OpenXR loader")?;
    let assets = stage.join("assets");
    std::fs::create_dir_all(&assets)?;
    // Assets the app reads through the AssetManager (the ONNX models join them with
    // live calibration).
    const ASSETS: &[&str] = &["toy.glb"];
    for a in ASSETS {
        std::fs::copy(root.join("assets").join(a), assets.join(a)).with_context(|| format!("bundling assets/{a}"))?;
    }
    let base = work.join("base.apk");
    run(Command::new("aapt2")
        .args(["link", "--warn-manifest-validation", "-I", FRAMEWORK_RES, "--manifest"])
        .arg(root.join("android/AndroidManifest.xml"))
        .arg("-A")
        .arg(&assets)
        .arg("-o")
        .arg(&base))?;
    // Native libraries stored uncompressed (extractNativeLibs=false: loaded in place).
    run(Command::new("zip").current_dir(&stage).args(["-q", "-0", "-r"]).arg(&base).arg("lib"))?;
    let aligned = work.join("aligned.apk");
    // The library is linked for 16 KiB pages (android-clang.sh), and is loaded in
    // place from the APK, so its data must start on a 16 KiB boundary too
    // (Android's 16 KB page-size guidance: `zipalign -P 16`). Debian's zipalign
    // has no -P, and -p aligns .so files to 4 KiB only: the whole alignment is
    // 16 KiB instead (every stored entry; a few KiB of padding each), and checked
    // after signing (`stored_libraries_page_aligned`).
    run(Command::new("zipalign").args(["-f", &PAGE_ALIGN.to_string()]).arg(&base).arg(&aligned))?;
    let out = root.join(format!("target/blind-augment-{profile}.apk"));
    let ks = keystore()?;
    run(Command::new("apksigner")
        .args(["sign", "--ks"])
        .arg(&ks)
        .args(["--ks-pass", "pass:android", "--key-pass", "pass:android", "--out"])
        .arg(&out)
        .arg(&aligned))?;
    run(Command::new("apksigner").args(["verify"]).arg(&out))?;
    let libraries = stored_libraries_page_aligned(&out)?;
    ensure!(libraries >= 2, "{libraries} stored libraries in the APK (the app's and the OpenXR loader expected)");
    check(&out, &built)?;
    let size = std::fs::metadata(&out)?.len();
    println!("{}", out.display());
    eprintln!("APK: {} ({:.1} MB), signed and verified", out.display(), size as f64 / 1e6);
    Ok(out)
}

/// The page size the library is built and stored for (bytes).
const PAGE_ALIGN: u64 = 16384;

/// Every stored (uncompressed) `.so` in the zip at `apk` starts its data on a
/// `PAGE_ALIGN` boundary; returns how many there are. Read from the zip's own
/// records (end of central directory → central headers → local headers).
fn stored_libraries_page_aligned(apk: &Path) -> Result<usize> {
    let z = std::fs::read(apk).with_context(|| format!("reading {}", apk.display()))?;
    let u16_at = |o: usize| -> Result<u64> {
        z.get(o..o + 2).map(|b| u16::from_le_bytes([b[0], b[1]]) as u64).context("zip record past the end")
    };
    let u32_at = |o: usize| -> Result<u64> {
        z.get(o..o + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64).context("zip record past the end")
    };
    let eocd = (0..z.len().saturating_sub(21))
        .rev()
        .find(|&o| z[o..o + 4] == [0x50, 0x4b, 0x05, 0x06])
        .context("no end of central directory: not a zip")?;
    let entries = u16_at(eocd + 10)?;
    let mut at = u32_at(eocd + 16)? as usize;
    let mut libraries = 0;
    for _ in 0..entries {
        ensure!(u32_at(at)? == 0x0201_4b50, "bad central directory header at {at}");
        let method = u16_at(at + 10)?;
        let (name_len, extra_len, comment_len) =
            (u16_at(at + 28)? as usize, u16_at(at + 30)? as usize, u16_at(at + 32)? as usize);
        let local = u32_at(at + 42)? as usize;
        let name =
            String::from_utf8_lossy(z.get(at + 46..at + 46 + name_len).context("name past the end")?).to_string();
        at += 46 + name_len + extra_len + comment_len;
        if !name.ends_with(".so") {
            continue;
        }
        ensure!(method == 0, "{name} is compressed: extractNativeLibs=false needs it stored");
        ensure!(u32_at(local)? == 0x0403_4b50, "bad local header for {name}");
        let data = local as u64 + 30 + u16_at(local + 26)? + u16_at(local + 28)?;
        ensure!(
            data.is_multiple_of(PAGE_ALIGN),
            "{name}: data at byte {data}, not on a {PAGE_ALIGN}-byte page boundary"
        );
        libraries += 1;
    }
    Ok(libraries)
}

/// What CI proves of the package (no headset here): the badging, the manifest's
/// activity, categories and permissions, and the library's imports and exports.
fn check(apk: &Path, unstripped: &Path) -> Result<()> {
    let badging = run(Command::new("aapt").args(["dump", "badging"]).arg(apk))?;
    for want in [
        "native-code: 'arm64-v8a'",
        "launchable-activity: name='android.app.NativeActivity'",
        "uses-permission: name='android.permission.CAMERA'",
        "uses-permission: name='horizonos.permission.HEADSET_CAMERA'",
        "uses-permission: name='com.oculus.permission.USE_SCENE'",
        "uses-permission: name='org.khronos.openxr.permission.OPENXR'",
        "sdkVersion:'29'",
    ] {
        ensure!(badging.contains(want), "aapt dump badging lacks {want:?}:\n{badging}");
    }
    let tree = run(Command::new("aapt").args(["dump", "xmltree"]).arg(apk).arg("AndroidManifest.xml"))?;
    for want in [
        "android.app.lib_name",
        "\"blind_augment\"",
        "com.oculus.intent.category.VR",
        "org.khronos.openxr.intent.category.IMMERSIVE_HMD",
        "android.intent.category.LAUNCHER",
        "com.oculus.supportedDevices",
        "quest3|quest3s",
    ] {
        ensure!(tree.contains(want), "the manifest lacks {want:?}");
    }
    let listing = run(Command::new("zip").arg("-sf").arg(apk))?;
    for want in ["lib/arm64-v8a/libblind_augment.so", "lib/arm64-v8a/libopenxr_loader.so", "assets/toy.glb"] {
        ensure!(listing.contains(want), "the APK lacks {want}");
    }
    let dynamic = run(Command::new("llvm-readelf-16").arg("-d").arg(unstripped))?;
    let needed: Vec<&str> = dynamic
        .lines()
        .filter(|l| l.contains("(NEEDED)"))
        .filter_map(|l| l.split('[').nth(1).and_then(|s| s.split(']').next()))
        .collect();
    for n in &needed {
        ensure!(
            ALLOWED_NEEDED.contains(n),
            "libblind_augment.so needs {n}, outside Android's NDK ABI {ALLOWED_NEEDED:?}"
        );
    }
    let syms = run(Command::new("llvm-readelf-16").args(["--dyn-syms", "-W"]).arg(unstripped))?;
    ensure!(
        syms.lines().any(|l| l.ends_with(" ANativeActivity_onCreate") && !l.contains(" UND ")),
        "libblind_augment.so does not export ANativeActivity_onCreate"
    );
    eprintln!("checked: badging, manifest, contents; NEEDED {needed:?}; exports ANativeActivity_onCreate");
    Ok(())
}

/// Where the app keeps its recordings on the headset: its external files folder
/// (`Context.getExternalFilesDir(null)`), `recordings/rec-<unix milliseconds>`.
const RECORDINGS: &str = "/sdcard/Android/data/org.blindaugment.app/files/recordings";

/// The newest `rec-<unix milliseconds>` in an `ls -1` listing.
fn newest_recording(listing: &str) -> Option<&str> {
    listing
        .lines()
        .map(str::trim)
        .filter_map(|l| l.strip_prefix("rec-").and_then(|n| n.parse::<u64>().ok()).map(|n| (n, l)))
        .max_by_key(|(n, _)| *n)
        .map(|(_, l)| l)
}

/// `cargo xtask pull-recording [DEST]`: the newest recording on the connected
/// headset, pulled with adb into DEST (default `target/recordings/`), and the
/// `calibrate` command its manifest gives for replaying it.
pub fn pull_recording(root: &Path, dest: Option<&Path>) -> Result<()> {
    ensure!(have("adb"), "adb not found (Debian: apt-get install adb), and the headset in developer mode, connected");
    let listing = run(Command::new("adb").args(["shell", "ls", "-1", RECORDINGS]))
        .with_context(|| format!("listing {RECORDINGS} on the headset (no recording made yet?)"))?;
    let Some(name) = newest_recording(&listing) else {
        bail!("{RECORDINGS} holds no recording (press the left thumbstick in the app to start and stop one)")
    };
    let dest = dest.map_or_else(|| root.join("target/recordings"), Path::to_path_buf);
    std::fs::create_dir_all(&dest).with_context(|| format!("creating {}", dest.display()))?;
    run(Command::new("adb").arg("pull").arg(format!("{RECORDINGS}/{name}")).arg(&dest))?;
    let local = dest.join(name);
    let manifest = std::fs::read_to_string(local.join("manifest.json"))
        .with_context(|| format!("{}: no manifest.json (a recording still being written?)", local.display()))?;
    let m: serde_json::Value =
        serde_json::from_str(&manifest).with_context(|| format!("{}/manifest.json", local.display()))?;
    eprintln!(
        "pulled {} ({} frames, stopped: {}); replay: cd {} && {}",
        local.display(),
        m["frames"],
        m["stopped"],
        local.display(),
        m["calibrate"].as_str().unwrap_or("blind-augment calibrate …")
    );
    Ok(())
}

/// `cargo xtask install`: adb install -r and start the activity (users with a headset).
pub fn install(root: &Path, release: bool) -> Result<()> {
    let profile = if release { "release" } else { "debug" };
    let apk = root.join(format!("target/blind-augment-{profile}.apk"));
    ensure!(
        apk.exists(),
        "{} not built: run cargo xtask apk{}",
        apk.display(),
        if release { " --release" } else { "" }
    );
    ensure!(have("adb"), "adb not found (Debian: apt-get install adb), and the headset in developer mode, connected");
    run(Command::new("adb").args(["install", "-r"]).arg(&apk))?;
    run(Command::new("adb").args(["shell", "am", "start", "-n", "org.blindaugment.app/android.app.NativeActivity"]))?;
    eprintln!("started; logs: adb logcat -s blind-augment");
    Ok(())
}

#[cfg(test)]
mod recording_tests {
    use super::newest_recording;

    #[test]
    fn the_newest_recording_is_the_largest_timestamp() {
        let ls = "rec-1700000100\nrec-999\nnotes.txt\nrec-1700000099\nrec-x\n";
        assert_eq!(newest_recording(ls), Some("rec-1700000100"));
        assert_eq!(newest_recording("other\n"), None);
    }
}
