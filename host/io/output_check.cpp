// The up-front check of a command's inputs and outputs.
#include "tfmatch/io/output_check.h"

#include <optional>
#include <stdexcept>
#include <system_error>

#include <sys/stat.h>
#include <unistd.h>

#include "tfmatch/io/atomic_file.h"

namespace fs = std::filesystem;

namespace tfm {
namespace {

// A file's identity: resolved path, and device and inode when it exists.
struct Identity {
  fs::path resolved;
  std::optional<std::pair<dev_t, ino_t>> inode;
};

Identity identify(const fs::path& path) {
  Identity id;
  std::error_code ec;
  id.resolved = fs::weakly_canonical(fs::absolute(path, ec), ec);
  if (ec) id.resolved = fs::absolute(path, ec).lexically_normal();
  struct stat st{};
  if (::stat(path.c_str(), &st) == 0) id.inode = std::make_pair(st.st_dev, st.st_ino);
  return id;
}

bool same_file(const Identity& a, const Identity& b) {
  if (a.inode && b.inode) return *a.inode == *b.inode;
  return a.resolved == b.resolved;
}

std::string quoted(const std::string& role, const fs::path& path) { return role + " " + path.string(); }

// The directory a new file or directory at `path` is created in.
fs::path parent_of(const fs::path& path) {
  const fs::path p = path.lexically_normal();
  const fs::path parent = (p.has_filename() ? p : p.parent_path()).parent_path();
  return parent.empty() ? fs::path(".") : parent;
}

void require_writable_directory(const fs::path& dir, const std::string& what) {
  std::error_code ec;
  if (!fs::exists(dir, ec)) throw std::runtime_error(what + ": directory " + dir.string() + " does not exist");
  if (!fs::is_directory(dir, ec)) throw std::runtime_error(what + ": " + dir.string() + " is not a directory");
  if (::access(dir.c_str(), W_OK | X_OK) != 0)
    throw std::runtime_error(what + ": directory " + dir.string() + " is not writable");
}

// As write_file_atomically() will find it: through a symbolic link, where the link leads.
void check_output_file(const fs::path& path, const std::string& what) {
  const fs::path target = output_target(path);
  try {
    check_replaceable_target(path, target);
  } catch (const std::runtime_error& e) {
    const std::string m = e.what();  // "PATH...: problem": the role leads instead
    throw std::runtime_error(what + m.substr(path.string().size()));
  }
  require_writable_directory(parent_of(target), what);
}

void check_output_directory(const fs::path& dir, const std::string& what) {
  std::error_code ec;
  if (fs::exists(dir, ec)) {
    if (!fs::is_directory(dir, ec)) throw std::runtime_error(what + ": exists and is not a directory");
    require_writable_directory(dir, what);
    return;
  }
  // Creatable: the first existing ancestor is a writable directory.
  fs::path ancestor = parent_of(dir);
  while (!fs::exists(ancestor, ec) && ancestor.has_parent_path() && ancestor.parent_path() != ancestor)
    ancestor = parent_of(ancestor);
  if (fs::exists(ancestor, ec) && !fs::is_directory(ancestor, ec))
    throw std::runtime_error(what + ": cannot be created: " + ancestor.string() + " is a file");
  require_writable_directory(ancestor, what + ": cannot be created");
}

}  // namespace

FilePlan& FilePlan::input(const fs::path& path, std::string role) {
  if (!path.empty()) files_.push_back({path, std::move(role), false});
  return *this;
}

FilePlan& FilePlan::input_spec(const std::string& spec, std::string role) {
  if (spec.empty()) return *this;
  std::error_code ec;
  fs::path path = spec;
  // As the readers resolve it: the whole spec when such a file exists, else what precedes the
  // last ':' (a missing file is the reader's error to report, with its own message).
  if (!fs::exists(path, ec)) {
    const auto colon = spec.rfind(':');
    if (colon != std::string::npos && colon > 0) path = spec.substr(0, colon);
  }
  return input(path, std::move(role));
}

FilePlan& FilePlan::output(const fs::path& path, std::string role) {
  if (!path.empty()) files_.push_back({path, std::move(role), true});
  return *this;
}

FilePlan& FilePlan::output_directory(const fs::path& dir, std::string role, std::vector<std::string> files) {
  if (!dir.empty()) directories_.push_back({dir, std::move(role), std::move(files)});
  return *this;
}

void FilePlan::check() const {
  // Every output, the files of output directories included, with its identity. Which file is
  // which is decided first: that one output would destroy another or an input is the message a
  // user needs, even where a directory is missing too.
  struct Out {
    fs::path path;
    std::string what;
    Identity id;
  };
  std::vector<Out> outputs;
  for (const Directory& d : directories_)
    for (const std::string& name : d.files)
      outputs.push_back({d.path / name, quoted(d.role, d.path) + " (its " + name + ")", identify(d.path / name)});
  for (const Entry& e : files_)
    if (e.output) outputs.push_back({e.path, quoted(e.role, e.path), identify(e.path)});
  for (size_t i = 0; i < outputs.size(); ++i)
    for (size_t k = 0; k < i; ++k)
      if (same_file(outputs[i].id, outputs[k].id))
        throw std::runtime_error(outputs[i].what + ": is the same file as " + outputs[k].what +
                                 "; one output would overwrite the other");
  for (const Entry& e : files_) {
    if (e.output) continue;
    const Identity in = identify(e.path);
    for (const Out& o : outputs)
      if (same_file(o.id, in))
        throw std::runtime_error(o.what + ": is the same file as " + quoted(e.role, e.path) +
                                 ", an input; writing it would destroy the input");
  }
  for (const Directory& d : directories_) check_output_directory(d.path, quoted(d.role, d.path));
  for (const Entry& e : files_)
    if (e.output) check_output_file(e.path, quoted(e.role, e.path));
}

}  // namespace tfm
