//! The in-app file browser behind **File → Open…**, **Open folder (DICOM)…**, **Open
//! session…** and **Save session…**.
//!
//! A native dialog needs an XDG desktop portal on Linux; without one (a bare X session, a
//! remote desktop, a cluster node) the dialog neither opens nor reports anything. This browser
//! is an egui window, so it works wherever the viewer's window does, and kittest drives it
//! like the rest of the UI.
//!
//! It holds one folder's listing ([`list_folder`]: read once per folder, on the UI thread,
//! at most [`MAX_ENTRIES`] names — a small probe like the session and raw checks in
//! [`super::files`]); folders come first, then files, each by name. Clicking selects (Ctrl or
//! Shift adds to the selection, for a series), double-clicking a folder enters it and a file
//! opens it; the **Folder** field takes a typed path on Enter. What the user picks becomes a
//! [`Command`], applied like any other.

use std::path::{Path, PathBuf};

use super::commands::Command;

/// What the browser is picking.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BrowsePurpose {
    /// One or more data files (several numbered ones open as a series).
    OpenData,
    /// A folder (a DICOM series).
    OpenFolder,
    OpenSession,
    SaveSession,
    /// Where File → Export isosurface… writes its mesh (PLY, STL or OBJ).
    ExportMesh,
    /// A volume on the shown grid to colour surface `usize` by.
    ColorVolume(usize),
}

impl BrowsePurpose {
    fn title(self) -> &'static str {
        match self {
            Self::OpenData => "Open volume data",
            Self::OpenFolder => "Open a folder (DICOM series)",
            Self::OpenSession => "Open session",
            Self::SaveSession => "Save session",
            Self::ExportMesh => "Export isosurface",
            Self::ColorVolume(_) => "Colour by another volume on the same grid",
        }
    }

    fn action(self) -> &'static str {
        match self {
            Self::OpenData | Self::OpenSession | Self::ColorVolume(_) => "Open",
            Self::OpenFolder => "Open folder",
            Self::SaveSession => "Save",
            Self::ExportMesh => "Export",
        }
    }

    /// Sessions are `.json` files: other files are not listed for them.
    fn lists(self, entry: &Entry) -> bool {
        match self {
            Self::OpenSession | Self::SaveSession => {
                entry.is_folder
                    || Path::new(&entry.name)
                        .extension()
                        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
            }
            Self::ExportMesh => {
                entry.is_folder
                    || Path::new(&entry.name).extension().is_some_and(|e| {
                        ["ply", "stl", "obj"]
                            .iter()
                            .any(|x| e.eq_ignore_ascii_case(x))
                    })
            }
            Self::OpenFolder => entry.is_folder,
            Self::OpenData | Self::ColorVolume(_) => true,
        }
    }

    /// Whether the browser names a file to write (a **File name** field) rather than picks.
    fn saves(self) -> bool {
        matches!(self, Self::SaveSession | Self::ExportMesh)
    }
}

/// One name in a folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Entry {
    pub name: String,
    pub is_folder: bool,
    pub bytes: u64,
}

/// The most names listed from one folder (a folder of a million DICOM slices stays usable).
pub const MAX_ENTRIES: usize = 20_000;

/// The folder's entries, folders first, then files, each by name (case-insensitive); the
/// flag says whether the listing stopped at [`MAX_ENTRIES`]. Names that are not UTF-8 are
/// shown lossily but still open (the path is rebuilt from the folder and the name).
pub fn list_folder(folder: &Path) -> Result<(Vec<Entry>, bool), String> {
    let read = std::fs::read_dir(folder).map_err(|e| format!("{}: {e}", folder.display()))?;
    let mut entries = Vec::new();
    let mut truncated = false;
    for item in read.flatten() {
        if entries.len() == MAX_ENTRIES {
            truncated = true;
            break;
        }
        // Follows symbolic links, so a link to a folder is entered like one.
        let meta = std::fs::metadata(item.path()).ok();
        entries.push(Entry {
            name: item.file_name().to_string_lossy().into_owned(),
            is_folder: meta.as_ref().is_some_and(std::fs::Metadata::is_dir),
            bytes: meta.map_or(0, |m| m.len()),
        });
    }
    entries.sort_by_key(|e| (!e.is_folder, e.name.to_lowercase()));
    Ok((entries, truncated))
}

/// The browser while it is open.
#[derive(Debug, Clone)]
pub struct FileBrowser {
    pub purpose: BrowsePurpose,
    pub folder: PathBuf,
    /// The **Folder** field as typed (taken on Enter).
    pub folder_text: String,
    pub entries: Vec<Entry>,
    pub truncated: bool,
    /// Selected names in `folder`.
    pub selected: Vec<String>,
    /// Saving: the **File name** field.
    pub file_name: String,
    pub show_hidden: bool,
    /// Why the last folder could not be listed.
    pub error: Option<String>,
}

/// What a frame of the browser ended with.
#[derive(Debug, Clone, PartialEq)]
pub enum BrowseOutcome {
    Open,
    Done(Command),
    Cancelled,
}

impl FileBrowser {
    /// The browser for `purpose`, listing `folder` (else the working directory, else `/`).
    pub fn new(purpose: BrowsePurpose, folder: Option<PathBuf>) -> Self {
        let mut b = Self {
            purpose,
            folder: PathBuf::new(),
            folder_text: String::new(),
            entries: Vec::new(),
            truncated: false,
            selected: Vec::new(),
            file_name: match purpose {
                BrowsePurpose::SaveSession => "session.json".to_string(),
                BrowsePurpose::ExportMesh => "isosurface.ply".to_string(),
                _ => String::new(),
            },
            show_hidden: false,
            error: None,
        };
        let candidates = folder
            .into_iter()
            .chain(std::env::current_dir().ok())
            .chain([PathBuf::from("/")]);
        for c in candidates {
            if b.enter(&c) {
                break;
            }
        }
        b
    }

    /// Lists `folder` and makes it current; on failure the current folder stays and the
    /// error is shown. Returns whether it worked.
    pub fn enter(&mut self, folder: &Path) -> bool {
        let folder = super::files::absolute_path(folder);
        match list_folder(&folder) {
            Ok((entries, truncated)) => {
                self.entries = entries;
                self.truncated = truncated;
                self.selected.clear();
                self.error = None;
                self.folder_text = folder.display().to_string();
                self.folder = folder;
                true
            }
            Err(e) => {
                self.error = Some(e);
                self.folder_text = self.folder.display().to_string();
                false
            }
        }
    }

    /// The command for the current selection (`None`: nothing to do yet).
    fn command(&self) -> Option<Command> {
        let picked: Vec<PathBuf> = self
            .selected
            .iter()
            .map(|name| self.folder.join(name))
            .collect();
        match self.purpose {
            BrowsePurpose::OpenData => (!picked.is_empty()).then_some(Command::OpenFiles(picked)),
            BrowsePurpose::OpenFolder => Some(Command::OpenFiles(vec![
                picked
                    .into_iter()
                    .next()
                    .unwrap_or_else(|| self.folder.clone()),
            ])),
            BrowsePurpose::OpenSession => picked.into_iter().next().map(Command::LoadSession),
            BrowsePurpose::SaveSession => self.save_path("json").map(Command::SaveSession),
            BrowsePurpose::ExportMesh => self.save_path("ply").map(Command::ExportMesh),
            BrowsePurpose::ColorVolume(surface) => picked
                .into_iter()
                .next()
                .map(|path| Command::AddColorVolume { surface, path }),
        }
    }

    /// The file the **File name** field names in the folder, with `extension` when it has
    /// none (`None` while the field is empty).
    fn save_path(&self, extension: &str) -> Option<PathBuf> {
        let name = self.file_name.trim();
        if name.is_empty() {
            return None;
        }
        let mut path = self.folder.join(name);
        if path.extension().is_none() {
            path.set_extension(extension);
        }
        Some(path)
    }

    /// Draws the browser window for one frame.
    pub fn ui(&mut self, ctx: &egui::Context) -> BrowseOutcome {
        let mut open = true;
        let mut outcome = BrowseOutcome::Open;
        egui::Window::new(self.purpose.title())
            .open(&mut open)
            .collapsible(false)
            .default_size([560.0, 420.0])
            .show(ctx, |ui| outcome = self.contents_ui(ui));
        if open {
            outcome
        } else {
            BrowseOutcome::Cancelled
        }
    }

    fn contents_ui(&mut self, ui: &mut egui::Ui) -> BrowseOutcome {
        let mut outcome = BrowseOutcome::Open;
        let mut go_to: Option<PathBuf> = None;
        ui.horizontal(|ui| {
            if ui.button("Up").on_hover_text("the parent folder").clicked()
                && let Some(parent) = self.folder.parent()
            {
                go_to = Some(parent.to_path_buf());
            }
            let l = ui.label("Folder");
            let edit = ui
                .add(egui::TextEdit::singleline(&mut self.folder_text).desired_width(f32::INFINITY))
                .labelled_by(l.id);
            if edit.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter)) {
                go_to = Some(PathBuf::from(self.folder_text.trim()));
            }
        });
        ui.checkbox(&mut self.show_hidden, "Show hidden files");
        if let Some(e) = &self.error {
            ui.colored_label(egui::Color32::from_rgb(255, 120, 100), e);
        }
        let mut activated: Option<Entry> = None;
        let modifiers = ui.input(|i| i.modifiers);
        egui::ScrollArea::vertical()
            .max_height(280.0)
            .auto_shrink([false, false])
            .show(ui, |ui| {
                for entry in self.entries.iter().filter(|e| {
                    self.purpose.lists(e) && (self.show_hidden || !e.name.starts_with('.'))
                }) {
                    let is_selected = self.selected.contains(&entry.name);
                    let text = if entry.is_folder {
                        format!("{}/", entry.name)
                    } else {
                        format!("{}  ({})", entry.name, human_bytes(entry.bytes))
                    };
                    let r = ui.selectable_label(is_selected, text);
                    if r.double_clicked() {
                        activated = Some(entry.clone());
                    } else if r.clicked() {
                        let adds = self.purpose == BrowsePurpose::OpenData
                            && (modifiers.command || modifiers.shift);
                        if !adds {
                            self.selected.clear();
                        }
                        if is_selected && adds {
                            self.selected.retain(|n| n != &entry.name);
                        } else {
                            self.selected.push(entry.name.clone());
                        }
                        if self.purpose.saves() && !entry.is_folder {
                            self.file_name.clone_from(&entry.name);
                        }
                    }
                }
            });
        if self.truncated {
            ui.label(format!("only the first {MAX_ENTRIES} names are listed"));
        }
        if self.purpose.saves() {
            ui.horizontal(|ui| {
                let l = ui.label("File name");
                ui.text_edit_singleline(&mut self.file_name)
                    .labelled_by(l.id);
            });
        }
        if let Some(Command::SaveSession(path) | Command::ExportMesh(path)) = self.command()
            && path.exists()
        {
            ui.label(format!(
                "{} exists: {} replaces it",
                path.file_name().unwrap_or_default().to_string_lossy(),
                self.purpose.action()
            ));
        }
        ui.horizontal(|ui| {
            let command = self.command();
            if ui
                .add_enabled(command.is_some(), egui::Button::new(self.purpose.action()))
                .clicked()
                && let Some(c) = command
            {
                // A selected folder is entered rather than opened (except a folder pick).
                match self.selected.as_slice() {
                    [one]
                        if self.purpose != BrowsePurpose::OpenFolder
                            && self.folder.join(one).is_dir() =>
                    {
                        go_to = Some(self.folder.join(one));
                    }
                    _ => outcome = BrowseOutcome::Done(c),
                }
            }
            if ui.button("Cancel").clicked() {
                outcome = BrowseOutcome::Cancelled;
            }
        });
        if let Some(entry) = activated {
            let path = self.folder.join(&entry.name);
            if entry.is_folder && self.purpose != BrowsePurpose::OpenFolder {
                go_to = Some(path);
            } else {
                self.selected = vec![entry.name.clone()];
                if self.purpose.saves() {
                    self.file_name = entry.name;
                }
                if let Some(c) = self.command() {
                    outcome = BrowseOutcome::Done(c);
                }
            }
        }
        if let Some(target) = go_to {
            // A typed path to a file opens it (or names the session to save).
            if target.is_file() {
                let folder = target.parent().map(Path::to_path_buf).unwrap_or_default();
                let name = target.file_name().map(|n| n.to_string_lossy().into_owned());
                if self.enter(&folder)
                    && let Some(name) = name
                {
                    self.selected = vec![name.clone()];
                    if self.purpose.saves() {
                        self.file_name = name;
                    }
                    if let Some(c) = self.command() {
                        outcome = BrowseOutcome::Done(c);
                    }
                }
            } else {
                self.enter(&target);
            }
        }
        outcome
    }
}

/// `bytes` for a listing: "812 B", "1.4 KiB", "97.0 MiB", "2.1 GiB".
fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 4] = ["KiB", "MiB", "GiB", "TiB"];
    if bytes < 1024 {
        return format!("{bytes} B");
    }
    let mut value = bytes as f64 / 1024.0;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    format!("{value:.1} {}", UNITS[unit])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_come_first_then_files_by_name() {
        let dir = tempfile::tempdir().unwrap();
        for f in ["b.nrrd", "A.vtu", ".hidden"] {
            std::fs::write(dir.path().join(f), b"12345").unwrap();
        }
        std::fs::create_dir(dir.path().join("zz")).unwrap();
        let (entries, truncated) = list_folder(dir.path()).unwrap();
        assert!(!truncated);
        let names: Vec<&str> = entries.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["zz", ".hidden", "A.vtu", "b.nrrd"]);
        assert!(entries[0].is_folder);
        assert!(entries[1..].iter().all(|e| !e.is_folder && e.bytes == 5));
        assert!(list_folder(&dir.path().join("missing")).is_err());
    }

    #[test]
    fn a_saved_session_gets_the_json_extension_and_sessions_list_only_json() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("s.json"), b"{}").unwrap();
        std::fs::write(dir.path().join("ct.nrrd"), b"x").unwrap();
        let mut b = FileBrowser::new(BrowsePurpose::SaveSession, Some(dir.path().into()));
        b.file_name = "mine".into();
        let folder = std::fs::canonicalize(dir.path()).unwrap();
        assert_eq!(
            b.command(),
            Some(Command::SaveSession(folder.join("mine.json")))
        );
        let listed: Vec<&str> = b
            .entries
            .iter()
            .filter(|e| b.purpose.lists(e))
            .map(|e| e.name.as_str())
            .collect();
        assert_eq!(listed, ["s.json"]);
    }

    #[test]
    fn an_exported_mesh_gets_the_ply_extension_and_meshes_are_listed() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["a.ply", "b.STL", "c.obj", "ct.nrrd"] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        let mut b = FileBrowser::new(BrowsePurpose::ExportMesh, Some(dir.path().into()));
        let folder = std::fs::canonicalize(dir.path()).unwrap();
        assert_eq!(
            b.command(),
            Some(Command::ExportMesh(folder.join("isosurface.ply")))
        );
        b.file_name = "bone".into();
        assert_eq!(
            b.command(),
            Some(Command::ExportMesh(folder.join("bone.ply")))
        );
        b.file_name = "bone.stl".into();
        assert_eq!(
            b.command(),
            Some(Command::ExportMesh(folder.join("bone.stl")))
        );
        let listed: Vec<&str> = b
            .entries
            .iter()
            .filter(|e| b.purpose.lists(e))
            .map(|e| e.name.as_str())
            .collect();
        assert_eq!(listed, ["a.ply", "b.STL", "c.obj"]);
    }

    #[test]
    fn sizes_read_in_binary_units() {
        assert_eq!(human_bytes(812), "812 B");
        assert_eq!(human_bytes(1536), "1.5 KiB");
        assert_eq!(human_bytes(97 << 20), "97.0 MiB");
    }
}
