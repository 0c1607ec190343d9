//! Cycling through the user's scenes: the scene the app started with, then glTF
//! files (on the headset, those pushed to the app's `scenes/` folder), each loaded
//! on a thread of its own when asked for, so the frame loop never parses a file.
//! A file that fails to load is named (`SceneCycle::errors`, the log) and skipped;
//! the starting scene never fails, so a cycle always ends somewhere drawable.

use crate::scene::Scene;
use std::path::PathBuf;
use std::sync::mpsc::{channel, Receiver, TryRecvError};

/// What `poll` hands the frame loop.
pub enum Ready {
    /// Back to the scene the app started with.
    Start,
    /// A scene loaded from `path` (index into the list, from 1).
    Loaded { index: usize, path: PathBuf, scene: Box<Scene> },
}

pub struct SceneCycle {
    paths: Vec<PathBuf>,
    /// 0: the starting scene; k: `paths[k - 1]`.
    current: usize,
    pending: Option<(usize, Receiver<Result<Scene, String>>)>,
    /// Presses made while a scene was loading: each moves on once it is ready.
    queued: usize,
    /// Files that failed to load, each with why.
    pub errors: Vec<String>,
}

impl SceneCycle {
    /// `paths`: the scenes after the starting one, in cycling order.
    pub fn new(paths: Vec<PathBuf>) -> Self {
        Self { paths, current: 0, pending: None, queued: 0, errors: vec![] }
    }

    /// How many scenes cycle (the starting one included).
    fn count(&self) -> usize {
        self.paths.len() + 1
    }

    pub fn current(&self) -> usize {
        self.current
    }

    /// The current scene's file name (None: the starting scene).
    pub fn current_name(&self) -> Option<String> {
        let path = self.paths.get(self.current.checked_sub(1)?)?;
        Some(path.file_name().map_or_else(|| path.display().to_string(), |n| n.to_string_lossy().into_owned()))
    }

    /// The starting scene is shown again (a loaded one could not be drawn).
    pub fn reset(&mut self) {
        self.current = 0;
        self.pending = None;
        self.queued = 0;
    }

    /// Ask for the scene after the current one (while one is loading, after it).
    pub fn request_next(&mut self) {
        if self.paths.is_empty() {
            return;
        }
        if self.pending.is_some() {
            self.queued += 1;
        } else {
            self.start((self.current + 1) % self.count());
        }
    }

    /// A press queued while loading: the next scene after `index`.
    fn next_queued(&mut self, index: usize) {
        if self.queued > 0 && self.pending.is_none() {
            self.queued -= 1;
            self.start((index + 1) % self.count());
        }
    }

    fn start(&mut self, index: usize) {
        let (tx, rx) = channel();
        if index > 0 {
            let path = self.paths[index - 1].clone();
            let spawned = std::thread::Builder::new().name("scene-load".into()).spawn(move || {
                let r = Scene::load(&path).map_err(|e| e.to_string());
                let _ = tx.send(r);
            });
            if let Err(e) = spawned {
                self.errors.push(format!("{}: no loader thread ({e})", self.paths[index - 1].display()));
                return;
            }
        } else {
            // The starting scene is already in memory: nothing to load.
            let _ = tx.send(Err(String::new()));
        }
        self.pending = Some((index, rx));
    }

    /// A scene ready to show, if one finished loading since the last call. A file
    /// that failed is recorded and the one after it requested.
    pub fn poll(&mut self) -> Option<Ready> {
        let (index, rx) = self.pending.as_ref()?;
        let index = *index;
        let result = match rx.try_recv() {
            Ok(r) => r,
            Err(TryRecvError::Empty) => return None,
            Err(TryRecvError::Disconnected) => Err("the loader thread ended without a result".into()),
        };
        self.pending = None;
        if index == 0 {
            // Already showing it (every other scene failed): nothing to rebuild.
            let changed = self.current != 0;
            self.current = 0;
            self.next_queued(0);
            return changed.then_some(Ready::Start);
        }
        let path = self.paths[index - 1].clone();
        match result {
            Ok(scene) => {
                for note in &scene.notes {
                    log::info!("scene {}: {note}", path.display());
                }
                self.current = index;
                self.next_queued(index);
                Some(Ready::Loaded { index, path, scene: Box::new(scene) })
            }
            Err(e) => {
                log::warn!("scene {} not loaded, skipped: {e}", path.display());
                self.errors.push(format!("{}: {e}", path.display()));
                self.start((index + 1) % self.count());
                None
            }
        }
    }
}

/// The glTF files (`.glb`, `.gltf`) directly in `dir`, in name order; none when the
/// folder does not exist.
pub fn scenes_in(dir: &std::path::Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| {
            d.flatten()
                .map(|e| e.path())
                .filter(|p| {
                    p.extension()
                        .and_then(|e| e.to_str())
                        .is_some_and(|e| e.eq_ignore_ascii_case("glb") || e.eq_ignore_ascii_case("gltf"))
                })
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    fn wait(c: &mut SceneCycle) -> Option<Ready> {
        let until = Instant::now() + Duration::from_secs(20);
        while Instant::now() < until {
            if let Some(r) = c.poll() {
                return Some(r);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        None
    }

    /// start → a good file → (a broken file, skipped and named) → start.
    #[test]
    fn broken_files_are_named_and_skipped() {
        let dir = std::env::temp_dir().join(format!("ba_scene_cycle_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("a.glb"), include_bytes!("../../assets/toy.glb")).unwrap();
        std::fs::write(dir.join("b.gltf"), b"{ not json").unwrap();
        std::fs::write(dir.join("notes.txt"), b"x").unwrap();
        let paths = scenes_in(&dir);
        assert_eq!(
            paths.iter().map(|p| p.file_name().unwrap().to_str().unwrap()).collect::<Vec<_>>(),
            ["a.glb", "b.gltf"]
        );
        let mut c = SceneCycle::new(paths);
        assert_eq!(c.count(), 3);
        c.request_next();
        assert!(matches!(wait(&mut c), Some(Ready::Loaded { index: 1, .. })));
        c.request_next();
        assert!(matches!(wait(&mut c), Some(Ready::Start)), "the broken file skipped, back to the start");
        assert_eq!(c.current(), 0);
        assert_eq!(c.errors.len(), 1);
        assert!(c.errors[0].contains("b.gltf"), "{:?}", c.errors);
        assert!(scenes_in(&dir.join("missing")).is_empty());
        // Two presses at once: the second waits for the first's scene, then the
        // broken file is skipped and, already on the start, nothing is handed over.
        c.request_next();
        c.request_next();
        assert!(matches!(wait(&mut c), Some(Ready::Loaded { index: 1, .. })));
        assert!(wait(&mut c).is_some_and(|r| matches!(r, Ready::Start)));
        assert_eq!(c.errors.len(), 2);
        let mut only_broken = SceneCycle::new(vec![dir.join("b.gltf")]);
        only_broken.request_next();
        assert!(wait(&mut only_broken).is_none(), "the start again, already shown: no rebuild");
        assert_eq!((only_broken.current(), only_broken.errors.len()), (0, 1));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
