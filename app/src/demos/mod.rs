//! The demo scenes: the thesis's applications (chapter 7) as FVRML files in `scenes/`, built
//! into the program so that `sculpt demo NAME` opens one with nothing else installed.
//!
//! Each demo is one file that every face reads the same way: the window authors its objects
//! into a new session (`EngineConfig::demo`), `sculpt render` pictures it, `sculpt touch`
//! feels it, and peers that join the session get it like any other ops.

use std::path::Path;

use formats::fvrml::{LoadOptions, Loaded, load};
use replication::shape::{IdSource, ShapePayload};

pub mod mri;
pub mod shark;

/// The demo `sculpt` and `sculpt demo` open when no name is given.
pub const DEFAULT_DEMO: &str = "watermelon";

/// One demo scene.
#[derive(Clone, Copy, Debug)]
pub struct Demo {
    /// What `sculpt demo NAME` takes (lowercase, no spaces).
    pub name: &'static str,
    /// A title for lists and the window's gallery.
    pub title: &'static str,
    /// What the scene shows and what to try, in a sentence or two.
    pub about: &'static str,
    /// The file in the repository, from its root.
    pub file: &'static str,
    /// The file's text.
    pub text: &'static str,
    /// Files it names (grid volumes), by their path relative to it, built in too.
    pub files: &'static [(&'static str, &'static [u8])],
}

/// Every demo, in the thesis's order.
pub const DEMOS: &[Demo] = &[
    Demo {
        name: "watermelon",
        title: "Watermelon",
        about: "A cut watermelon (Figure 7.1): push through the rind's tension and it pops; the \
                flesh is crunchy inside a hard shell.",
        file: "scenes/watermelon.wrl",
        text: include_str!("../../../scenes/watermelon.wrl"),
        files: &[],
    },
    Demo {
        name: "wind",
        title: "Tangible wind",
        about: "A turning fan whose airflow is a force field inside an invisible cone: it \
                pushes along the cone's axis, strongest near the fan, and stops outside it.",
        file: "scenes/wind.wrl",
        text: include_str!("../../../scenes/wind.wrl"),
        files: &[],
    },
    Demo {
        name: "whirlpool",
        title: "Whirlpool",
        about: "Water in a basin with a helical force field (Figures 7.3 and 7.4): it pulls \
                round, in and down.",
        file: "scenes/whirlpool.wrl",
        text: include_str!("../../../scenes/whirlpool.wrl"),
        files: &[],
    },
    Demo {
        name: "shark",
        title: "Moving shark",
        about: "A shark swims round a rock once every 10 seconds; its body and the wake \
                behind it move with it: hold the hand just outside its circle and the wake \
                tugs it along as the shark passes; reach in to feel its skin and body.",
        file: "scenes/shark.wrl",
        text: include_str!("../../../scenes/shark.wrl"),
        files: &[],
    },
    Demo {
        name: "campus",
        title: "Tangible campus",
        about: "A small campus of polygon buildings made touchable by invisible function \
                containers (Figures 7.7 and 7.8): the walls are solid, the lawn is soft.",
        file: "scenes/campus.wrl",
        text: include_str!("../../../scenes/campus.wrl"),
        files: &[],
    },
    Demo {
        name: "classroom",
        title: "Classroom",
        about: "A block of clay on a workbench that a class shapes together (Figures 7.9 and \
                7.10): load a shape with `shape:`, colour it, give it a density, dig holes \
                with a small cylinder and paint friction on with a big one.",
        file: "scenes/classroom.wrl",
        text: include_str!("../../../scenes/classroom.wrl"),
        files: &[],
    },
    Demo {
        name: "mri",
        title: "MRI segmentation",
        about: "A head scan as a function (Figure 7.11): a sampled grid, cut open, coloured \
                and made dense by its tissue. Touch it with the sampling sphere, which takes \
                the colour of the density under it: skull hard, brain soft, the tumour \
                hardest, the ventricles hollow.",
        file: "scenes/mri.wrl",
        text: include_str!("../../../scenes/mri.wrl"),
        files: &[("head.nrrd", include_bytes!("../../../scenes/head.nrrd"))],
    },
    Demo {
        name: "femur",
        title: "Femur drilling",
        about: "A femur with marrow softer than its bone (Figure 7.14's surgical session): \
                carve into it with a cylinder tool, paint density, undo, and export the result.",
        file: "scenes/femur.wrl",
        text: include_str!("../../../scenes/femur.wrl"),
        files: &[],
    },
];

/// The demo called `name`, or an error that lists the names there are.
pub fn find(name: &str) -> Result<&'static Demo, String> {
    DEMOS.iter().find(|d| d.name == name).ok_or_else(|| {
        let names: Vec<&str> = DEMOS.iter().map(|d| d.name).collect();
        format!(
            "no demo is called `{name}`; there are: {}",
            names.join(", ")
        )
    })
}

impl Demo {
    /// The scene as FVRML loads it, with its built-in files.
    pub fn load(&self, options: &LoadOptions) -> Result<Loaded, String> {
        let mut built_in = |url: &str| {
            self.files
                .iter()
                .find(|(name, _)| *name == url)
                .map(|(_, bytes)| bytes.to_vec())
                .ok_or_else(|| format!("the demo scene `{}` has no file `{url}`", self.name))
        };
        load(self.text, options, &mut built_in)
            .map_err(|e| format!("the demo scene `{}` does not load: {e}", self.name))
    }

    /// The scene's ops, as an import of its file plans them: its groups (parents first),
    /// then its objects in their groups, with ids from `first` on.
    pub fn payloads(&self, first: IdSource) -> Result<Vec<ShapePayload>, String> {
        let loaded = self.load(&LoadOptions::default())?;
        crate::transfer::scene_payloads(Path::new(self.file), &loaded.scene, first)
            .map(|imported| imported.payloads)
            .map_err(|e| e.to_string())
    }
}

impl Demo {
    /// The name of the demo's own session store under the sessions folder: `demo` for the
    /// default one (where `sculpt` alone has always kept it), `demo-NAME` for the others.
    pub fn store_dir_name(&self) -> String {
        if self.name == DEFAULT_DEMO {
            "demo".into()
        } else {
            format!("demo-{}", self.name)
        }
    }
}

/// `sculpt demo --list`: one line per demo, name, title and what it shows.
pub fn list_text() -> String {
    let width = DEMOS.iter().map(|d| d.name.len()).max().unwrap_or(0);
    let mut out = String::new();
    for demo in DEMOS {
        out.push_str(&format!(
            "{:width$}  {}: {}\n",
            demo.name, demo.title, demo.about
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_demo_loads_without_warnings_and_has_objects() {
        for demo in DEMOS {
            let loaded = demo.load(&LoadOptions::default()).unwrap();
            assert!(!loaded.scene.is_empty(), "{}", demo.name);
            let warnings: Vec<String> = loaded.warnings.iter().map(ToString::to_string).collect();
            assert!(warnings.is_empty(), "{}: {warnings:?}", demo.name);
        }
    }

    /// A demo opens as a session by authoring its objects as ops: each must fit in one.
    #[test]
    fn every_demo_plans_as_ops_that_fit() {
        for demo in DEMOS {
            let payloads = demo
                .payloads(IdSource::first(replication::PeerId([1; 32])))
                .unwrap_or_else(|e| panic!("{}: {e}", demo.name));
            assert!(!payloads.is_empty(), "{}", demo.name);
        }
    }

    #[test]
    fn names_are_unique_and_found() {
        for demo in DEMOS {
            assert_eq!(find(demo.name).unwrap().file, demo.file);
            assert_eq!(DEMOS.iter().filter(|d| d.name == demo.name).count(), 1);
        }
        assert!(find(DEFAULT_DEMO).is_ok());
        let error = find("shark fin").unwrap_err();
        assert!(error.contains("watermelon, wind"), "{error}");
    }

    /// Every file of `scenes/` is a demo, and every demo's file is there with the text built in.
    #[test]
    fn the_scenes_folder_and_the_list_agree() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let mut files: Vec<String> = std::fs::read_dir(root.join("scenes"))
            .unwrap()
            .map(|e| format!("scenes/{}", e.unwrap().file_name().to_string_lossy()))
            .filter(|f| f.ends_with(".wrl"))
            .collect();
        files.sort();
        let mut listed: Vec<String> = DEMOS.iter().map(|d| d.file.to_string()).collect();
        listed.sort();
        assert_eq!(files, listed);
        for demo in DEMOS {
            assert_eq!(
                std::fs::read_to_string(root.join(demo.file)).unwrap(),
                demo.text
            );
        }
    }
}
