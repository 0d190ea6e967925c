// The shared render flags.
#include "render_options.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <stdexcept>

#include "cli.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/model/builtin_tf.h"
#include "tfmatch/model/color_bar.h"
#include "tfmatch/model/color_spaces.h"
#include "tfmatch/model/field_mapping.h"

namespace tfm::cli {

void note_diverging_middle(const std::string& tf_spec, const TransferFunction& tf, bool range_given,
                           const FieldRange& range, const std::string& flag) {
  if (range_given || tf.range || tf_spec.empty()) return;
  if (const std::optional<BuiltinTf> builtin = builtin_tf_named_by(tf_spec))
    if (const std::string note = diverging_middle_note(*builtin, range, flag); !note.empty()) print_note(note);
}

FieldRange field_range_for(const Volume& v, const TransferFunction& tf, const std::string& flag_value,
                           const std::string& flag, bool allow, const std::string& tf_spec) {
  FieldRange user;
  if (!flag_value.empty()) user = parse_range(flag_value, flag);
  const FieldRange* given = !flag_value.empty() ? &user : (tf.range ? &*tf.range : nullptr);
  const FieldRange range = resolve_range(v.values, given, v.name);
  if (given) {
    const std::string source = flag_value.empty() ? "the TF file's range" : "the " + flag + " range";
    const std::string w = check_range_coverage(v.values, range, v.name, source, allow);
    if (!w.empty()) std::cerr << "tfmatch: warning: " << w << "\n";
  }
  note_diverging_middle(tf_spec, tf, !flag_value.empty(), range, flag);
  return range;
}

std::array<double, 3> parse_color(const std::string& text, const std::string& flag) {
  auto fail = [&] {
    throw CLI::ValidationError(flag, "expected white, black, gray, #rrggbb or r,g,b in [0,1], got '" + text + "'");
  };
  if (text == "white") return {1, 1, 1};
  if (text == "black") return {0, 0, 0};
  if (text == "gray" || text == "grey") return {0.5, 0.5, 0.5};
  std::array<double, 3> c{};
  if (text.size() == 7 && text[0] == '#') {
    for (int k = 0; k < 3; ++k) {
      const std::string hex = text.substr(1 + 2 * k, 2);
      if (!std::isxdigit(static_cast<unsigned char>(hex[0])) || !std::isxdigit(static_cast<unsigned char>(hex[1])))
        fail();
      c[k] = double(std::strtol(hex.c_str(), nullptr, 16)) / 255.0;
    }
    return c;
  }
  size_t pos = 0;
  for (int k = 0; k < 3; ++k) {
    const size_t end = k < 2 ? text.find(',', pos) : text.size();
    if (end == std::string::npos) fail();
    const std::string part = text.substr(pos, end - pos);
    char* stop = nullptr;
    c[k] = std::strtod(part.c_str(), &stop);
    if (part.empty() || *stop != '\0' || !(c[k] >= 0 && c[k] <= 1)) fail();
    pos = end + 1;
  }
  return c;
}

void add_marker_option(CLI::App* sub, std::vector<std::string>& markers) {
  sub->add_option("--marker", markers,
                  "Draw a red dot at this grid point: I,J,K (I along x) or lon=..,lat=..,level=..; repeatable")
      ->expected(1)->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)->group("Rendering");
}

void add_histogram_option(CLI::App* sub, std::string& histogram) {
  sub->add_option("--histogram", histogram,
                  "Report TF plots: 'log' bars log(1 + count) (a dominant value does not flatten the rest) or "
                  "'linear' counts (shows how dominant it is); each plot says which")
      ->check(CLI::IsMember({"log", "linear"}))->capture_default_str()->group("Rendering");
}

void add_slice_point_option(CLI::App* sub, std::string& point) {
  sub->add_option("--slice-point", point,
                  "The report's axis-aligned slices go through this voxel: I,J,K or lon=..,lat=..,level=.. "
                  "(default: the first --marker, else the middle)")
      ->group("Rendering");
}

GridIndex resolve_point(const Volume& grid, const std::string& text, const std::string& what) {
  std::vector<std::string> warnings;
  const GridIndex p = resolve_grid_point(grid, text, what, &warnings);
  for (const std::string& w : warnings) print_warning(w);
  return p;
}

std::optional<GridIndex> resolve_slice_point(const Volume& grid, const std::string& text) {
  if (text.empty()) return std::nullopt;
  try {
    return resolve_point(grid, text, "--slice-point");
  } catch (const std::invalid_argument& e) {
    throw CLI::ValidationError("--slice-point", e.what());
  }
}

std::vector<GridIndex> resolve_markers(const Volume& grid, const std::vector<std::string>& texts) {
  std::vector<GridIndex> out;
  for (const auto& t : texts) {
    try {
      out.push_back(resolve_point(grid, t, "--marker"));
    } catch (const std::invalid_argument& e) {
      throw CLI::ValidationError("--marker", e.what());
    }
  }
  return out;
}

RenderChoices render_choices(const CLI::App& sub) {
  RenderChoices c;
  c.camera_angles = sub.count("--azimuth") + sub.count("--elevation") > 0;
  c.opacity_scale = sub.count("--opacity-scale") > 0;
  c.image_size = sub.count("--width") + sub.count("--height") > 0;
  return c;
}

void add_render_options(CLI::App* sub, RenderSettings& s) {
  const std::string g = "Rendering";
  sub->add_option("--azimuth", s.camera.azimuth_deg,
                  "Camera azimuth about the grid's z axis, degrees (thin grids: -90 with elevation 90, a map with "
                  "north up)")
      ->capture_default_str()->group(g);
  sub->add_option("--elevation", s.camera.elevation_deg, "Camera elevation above the xy plane, degrees (-90..90)")
      ->check(CLI::Range(-90.0, 90.0))->capture_default_str()->group(g);
  sub->add_option("--distance", s.camera.distance,
                  "Camera distance from the box centre, in bounding-sphere radii; 0 frames the box (fits every "
                  "corner in the image, whatever the box's shape)")
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            char* end = nullptr;
            const double d = std::strtod(text.c_str(), &end);
            if (text.empty() || *end != '\0' || !(d == 0 || (d > 1 && d <= 1e4)))
              return "must be 0 (framed) or in (1, 10000] bounding-sphere radii, got '" + text + "'";
            return "";
          },
          "0|(1,10000]"))
      ->capture_default_str()->group(g);
  sub->add_option("--z-scale", s.z_scale, "Vertical exaggeration: the box's z extent times this (thin geophysical grids)")
      ->check(CLI::Range(0.001, 1e4))->capture_default_str()->group(g);
  sub->add_flag_callback("--no-outline", [&s] { s.box_outline = false; }, "Do not draw the box's outline on pictures")
      ->group(g);
  sub->add_option("--fov", s.camera.fov_deg, "Vertical field of view, degrees")
      ->check(CLI::Range(0.1, 179.0))->capture_default_str()->group(g);
  sub->add_option("--width", s.width, "Image width in pixels")->check(CLI::Range(1u, 16384u))
      ->capture_default_str()->group(g);
  sub->add_option("--height", s.height, "Image height in pixels")->check(CLI::Range(1u, 16384u))
      ->capture_default_str()->group(g);
  sub->add_option("--step", s.step_voxels, "Ray-marching step, in voxels of the finest axis")
      ->check(CLI::Range(0.01, 64.0))->capture_default_str()->group(g);
  sub->add_option("--opacity-scale", s.opacity_scale,
                  "Extinction of TF opacity 1 per box length (sigma = a * scale); thin grids (<= 4 levels, or 8 "
                  "times wider than tall): the default times box length / height (a note gives the factor; a "
                  "scale given is used as it is)")
      ->check(non_negative())->capture_default_str()->group(g);
  sub->add_option("--termination", s.termination_opacity, "Stop a ray once its opacity reaches this (< 1)")
      ->check(CLI::Range(0.01, 0.9999))->capture_default_str()->group(g);
  sub->add_option_function<std::string>(
         "--background",
         [&s](const std::string& v) {
           // Given as shown on screen (sRGB), composited in linear RGB like the TF colours.
           const std::array<double, 3> c = parse_color(v, "--background");
           for (int k = 0; k < 3; ++k) s.background[k] = srgb_to_linear(c[k]);
         },
         "Background as shown (sRGB): white, black, gray, #rrggbb or r,g,b (default white)")
      ->group(g);
}

void add_color_bar_flag(CLI::App* sub, bool& on) {
  sub->add_flag("--color-bar,!--no-color-bar", on,
                "Add a colour bar of the TF with its value range in a " + std::to_string(kColorBarStripHeight) +
                    "-pixel strip beneath the picture (" + (on ? "default; --no-color-bar leaves it out" : "default off") +
                    ")")
      ->group("Rendering");
}

std::vector<std::string> given_picture_flags(const CLI::App& sub, std::initializer_list<const char*> also,
                                             std::initializer_list<const char*> except) {
  auto listed = [](std::initializer_list<const char*> names, const std::string& name) {
    return std::any_of(names.begin(), names.end(), [&](const char* n) { return name == n; });
  };
  std::vector<std::string> given;
  for (const CLI::Option* o : sub.get_options()) {
    const std::string name = o->get_name();
    if (o->count() == 0 || listed(except, name) || (o->get_group() != "Rendering" && !listed(also, name))) continue;
    given.push_back(name == "--color-bar" && !o->as<bool>() ? "--no-color-bar" : name);  // one option, two names
  }
  return given;
}

CLI::ValidationError unused_picture_flags(const std::vector<std::string>& flags, const std::string& picture,
                                          const std::string& fix) {
  std::string names;
  for (const std::string& f : flags) names += (names.empty() ? "" : ", ") + f;
  const bool one = flags.size() == 1;
  return CLI::ValidationError(names, std::string(one ? "shapes " : "shape ") + picture + ": " + fix + ", or leave " +
                                         (one ? "it" : "them") + " out");
}

void add_picture_color_bar(Image& picture, const TransferFunction& tf, const FieldRange& range,
                           const std::string& title, const RenderSettings& settings) {
  if (std::optional<Image> framed = with_color_bar(picture, tf, range, title, settings.background))
    picture = std::move(*framed);
  else
    print_note("no colour bar: the picture is narrower than " + std::to_string(kColorBarMinWidth) +
               " pixels, too narrow for one");
}

}  // namespace tfm::cli
