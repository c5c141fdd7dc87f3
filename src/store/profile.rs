//! The AWS shared configuration files, as the AWS CLI and SDKs read them: a named profile's
//! static keys, region and endpoint from `~/.aws/credentials` and `~/.aws/config` (or the
//! files `AWS_SHARED_CREDENTIALS_FILE` and `AWS_CONFIG_FILE` name), the profile chosen by
//! `AWS_PROFILE` (else `default`). The environment's own `AWS_*` variables win over the files,
//! as in the SDKs. A profile that gets its keys another way (an assumed role, SSO, an
//! external process) is refused, naming the profile and the setting: this tool does not run
//! those flows, and the instance role it would otherwise fall back to is not what the user
//! chose.

use std::collections::HashMap;
use std::path::PathBuf;

/// What one profile says, each setting where the files give it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct Profile {
    /// The profile's name.
    pub name: String,
    pub access_key_id: Option<String>,
    pub secret_access_key: Option<String>,
    pub session_token: Option<String>,
    pub region: Option<String>,
    pub endpoint_url: Option<String>,
}

/// Settings that get keys in a way this tool does not follow.
const UNFOLLOWED: [&str; 5] =
    ["role_arn", "credential_process", "sso_session", "sso_start_url", "web_identity_token_file"];

/// The profile `AWS_PROFILE` (else `default`) names, read from the shared files `var` locates
/// (`var` reads the environment); `Ok(None)` where neither file has it and `AWS_PROFILE` is
/// not set. `Err` says why the profile cannot be used.
pub(crate) fn load(var: &dyn Fn(&str) -> Option<String>) -> Result<Option<Profile>, String> {
    let home = var("HOME").map(PathBuf::from);
    let file = |env: &str, name: &str| {
        var(env).map(PathBuf::from).or_else(|| home.as_ref().map(|h| h.join(".aws").join(name)))
    };
    let named = var("AWS_PROFILE").filter(|p| !p.is_empty());
    let name = named.clone().unwrap_or_else(|| "default".into());
    let mut found = false;
    let mut settings = HashMap::new();
    // The config file's section is `[profile NAME]` (`[default]` for the default); the
    // credentials file's `[NAME]`. Keys in the credentials file win, as in the SDKs.
    let sources = [("AWS_CONFIG_FILE", "config", true), ("AWS_SHARED_CREDENTIALS_FILE", "credentials", false)];
    for (env, default_name, is_config) in sources {
        let Some(path) = file(env, default_name) else { continue };
        let text = match std::fs::read_to_string(&path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound && var(env).is_none() => continue,
            Err(e) => return Err(format!("{}: {e}", path.display())),
        };
        let section = match (is_config, name.as_str()) {
            (true, "default") => "default".to_string(),
            (true, name) => format!("profile {name}"),
            (false, name) => name.to_string(),
        };
        if let Some(found_here) = section_of(&text, &section) {
            found = true;
            settings.extend(found_here);
        }
    }
    if !found {
        return match named {
            Some(name) => Err(format!("AWS_PROFILE={name}: no such profile in the AWS config or credentials file")),
            None => Ok(None),
        };
    }
    if let Some(key) = UNFOLLOWED.iter().find(|k| settings.contains_key(**k)) {
        return Err(format!(
            "the AWS profile '{name}' gets its keys through {key}, which this tool does not follow: export them (`aws configure export-credentials --profile {name} --format env`)"
        ));
    }
    let mut take = |key: &str| settings.remove(key).filter(|v| !v.is_empty());
    let profile = Profile {
        access_key_id: take("aws_access_key_id"),
        secret_access_key: take("aws_secret_access_key"),
        session_token: take("aws_session_token"),
        region: take("region"),
        endpoint_url: take("endpoint_url"),
        name,
    };
    if profile.access_key_id.is_some() != profile.secret_access_key.is_some() {
        return Err(format!(
            "the AWS profile '{}' has only one of aws_access_key_id and aws_secret_access_key",
            profile.name
        ));
    }
    Ok(Some(profile))
}

/// The `key = value` settings of `[section]` in an INI file as the AWS files write it (`#`
/// and `;` comments, indented lines of a nested block such as `s3 =` skipped); `None` where
/// the file has no such section. A section given twice adds up, the later value winning.
fn section_of(text: &str, section: &str) -> Option<HashMap<String, String>> {
    let mut inside = false;
    let mut found = None;
    for line in text.lines() {
        if line.starts_with([' ', '\t']) {
            continue; // a nested block's setting (`s3 =` then indented lines)
        }
        let line = line.trim();
        if line.is_empty() || line.starts_with(['#', ';']) {
            continue;
        }
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            inside = name.split_whitespace().collect::<Vec<_>>().join(" ") == section;
            if inside {
                found.get_or_insert_with(HashMap::new);
            }
            continue;
        }
        if let (true, Some((key, value))) = (inside, line.split_once('=')) {
            let settings = found.get_or_insert_with(HashMap::new);
            settings.insert(key.trim().to_ascii_lowercase(), value.trim().to_string());
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads the profile with `vars` as the environment and the two files' texts (where given).
    fn load_with(
        vars: &[(&str, &str)],
        config: Option<&str>,
        credentials: Option<&str>,
    ) -> Result<Option<Profile>, String> {
        let dir = tempfile::tempdir().unwrap();
        let aws = dir.path().join(".aws");
        std::fs::create_dir(&aws).unwrap();
        for (name, text) in [("config", config), ("credentials", credentials)] {
            if let Some(text) = text {
                std::fs::write(aws.join(name), text).unwrap();
            }
        }
        let home = dir.path().to_string_lossy().into_owned();
        let var = |name: &str| match name {
            "HOME" => Some(home.clone()),
            _ => vars.iter().find(|(k, _)| *k == name).map(|(_, v)| v.to_string()),
        };
        load(&var)
    }

    const CONFIG: &str = "# the AWS CLI's layout\n[default]\nregion = eu-west-1\n\n[profile lab]\nregion=us-east-2\nendpoint_url = http://127.0.0.1:9000\ns3 =\n  addressing_style = path\n";
    const CREDENTIALS: &str = "[default]\naws_access_key_id = AKDEFAULT\naws_secret_access_key = sdefault\n\n[lab]\n; a comment\naws_access_key_id=AKLAB\naws_secret_access_key = slab\naws_session_token = tlab\n";

    #[test]
    fn the_named_profile_takes_both_files_settings() {
        let lab = load_with(&[("AWS_PROFILE", "lab")], Some(CONFIG), Some(CREDENTIALS)).unwrap().unwrap();
        assert_eq!(
            lab,
            Profile {
                name: "lab".into(),
                access_key_id: Some("AKLAB".into()),
                secret_access_key: Some("slab".into()),
                session_token: Some("tlab".into()),
                region: Some("us-east-2".into()),
                endpoint_url: Some("http://127.0.0.1:9000".into()),
            }
        );
        let default = load_with(&[], Some(CONFIG), Some(CREDENTIALS)).unwrap().unwrap();
        assert_eq!((default.name.as_str(), default.access_key_id.as_deref()), ("default", Some("AKDEFAULT")));
        assert_eq!((default.region.as_deref(), default.endpoint_url), (Some("eu-west-1"), None));
    }

    #[test]
    fn no_files_is_no_profile_but_a_named_one_must_exist() {
        assert_eq!(load_with(&[], None, None), Ok(None));
        let err = load_with(&[("AWS_PROFILE", "nope")], Some(CONFIG), Some(CREDENTIALS)).unwrap_err();
        assert!(err.contains("AWS_PROFILE=nope: no such profile"), "{err}");
        // A file the environment names must be there.
        let err = load_with(&[("AWS_CONFIG_FILE", "/nonexistent/aws-config")], None, None).unwrap_err();
        assert!(err.contains("/nonexistent/aws-config"), "{err}");
    }

    #[test]
    fn keys_got_another_way_are_refused_by_name() {
        let config = "[profile admin]\nrole_arn = arn:aws:iam::1:role/x\nsource_profile = default\n";
        let err = load_with(&[("AWS_PROFILE", "admin")], Some(config), None).unwrap_err();
        assert!(err.contains("'admin'") && err.contains("role_arn") && err.contains("export-credentials"), "{err}");
        let half = "[default]\naws_access_key_id = AK\n";
        let err = load_with(&[], None, Some(half)).unwrap_err();
        assert!(err.contains("only one of aws_access_key_id and aws_secret_access_key"), "{err}");
    }
}
