//! `tnd objects`: list an object set, or export the built-in set as meshes plus an `objects.json` manifest.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, Subcommand};
use tactile_derender::objects::ObjectSet;

#[derive(Args, Debug)]
pub struct ObjectsArgs {
    #[command(subcommand)]
    pub command: ObjectsCommand,
}

#[derive(Subcommand, Debug)]
pub enum ObjectsCommand {
    /// Print the objects of a set as JSON lines (name, family, split, symmetry, triangles, closed).
    List {
        /// "builtin" or a directory with objects.json.
        #[arg(long, default_value = "builtin")]
        objects: String,
    },
    /// Write the built-in set to DIR (OBJ meshes in metres + objects.json).
    Export { dir: PathBuf },
}

pub fn run(a: ObjectsArgs) -> Result<()> {
    match a.command {
        ObjectsCommand::List { objects } => {
            let set = ObjectSet::open(&objects)?;
            for e in set.entries() {
                let report = set.mesh(&e.name)?.report();
                let mut v = serde_json::to_value(e)?;
                if let Some(obj) = v.as_object_mut() {
                    obj.insert("triangles".into(), report.triangles.into());
                    obj.insert("closed".into(), report.closed.into());
                }
                println!("{v}");
            }
        }
        ObjectsCommand::Export { dir } => {
            let set = ObjectSet::builtin();
            set.export(&dir)?;
            println!(
                "{}",
                serde_json::json!({"exported": set.entries().len(), "dir": dir})
            );
        }
    }
    Ok(())
}
