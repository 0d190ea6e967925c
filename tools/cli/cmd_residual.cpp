// `tfmatch residual`: the residual map || premul(T_r(F_r)) - premul(T_o(F_o)) ||_2 per voxel,
// saved as float32 raw, and optionally rendered with the residual TF into a PNG.
#include <cmath>
#include <iostream>
#include <optional>
#include <regex>

#include "cli.h"
#include "input_options.h"
#include "output_options.h"
#include "render_options.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/io/volume_vti.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/kernels/residual.h"
#include "tfmatch/model/field_mapping.h"  // no_data
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/report/png_io.h"

namespace tfm::cli {
namespace {

struct ResidualArgs {
  std::string ref, ref_tf, field, field_tf, out, image;
  std::vector<std::string> image_flags;  // rendering flags and --display-range given
  std::string ref_range, field_range, display_range;
  bool allow_out_of_range = false;
  bool color_bar = true;  // the display range is the data's own: the picture must say it
  VolumeFlags volume_flags;
  RenderSettings settings;
  RenderChoices chosen;
};

int run(ResidualArgs a) {
  set_progress_enabled(!globals().quiet);
  FilePlan()
      .input_spec(a.ref, "--ref")
      .input_spec(a.ref_tf, "--ref-tf")
      .input_spec(a.field, "--field")
      .input_spec(a.field_tf, "--field-tf")
      .output(a.out, "--out")
      .output(a.image, "--image")
      .check();
  // Picture settings without a picture would be dropped without a word.
  if (a.image.empty() && !a.image_flags.empty())
    throw unused_picture_flags(a.image_flags, "the residual's picture", "add --image FILE.png");
  std::optional<FieldRange> display;
  if (!a.display_range.empty()) display = parse_range(a.display_range, "--display-range");
  if (!a.image.empty()) validate(a.settings);
  auto ctx = make_context();
  if (!a.image.empty()) check_render_size(*ctx, a.settings);
  OutputBatch outputs;
  const VolumeOptions vo = a.volume_flags.options({a.ref, a.field});
  auto [ref, field] = load_volume_pair(a.ref, a.field, vo);
  require_same_grid(ref, field);
  if (const std::string w = grid_geometry_warning(ref, field); !w.empty()) print_warning(w);
  if (!a.image.empty())  // the render settings shape --image alone
    if (const std::string note = apply_grid_defaults(a.settings, ref.dims, ref.spacing, a.chosen); !note.empty())
      print_note(note);
  std::vector<std::string> notes;
  TransferFunction ref_tf = read_transfer_function(a.ref_tf, {}, &notes);
  TransferFunction field_tf = read_transfer_function(a.field_tf, {}, &notes);
  for (const std::string& n : notes) print_note(n);
  const FieldRange ref_range = field_range_for(ref, ref_tf, a.ref_range, "--ref-range", a.allow_out_of_range, a.ref_tf);
  const FieldRange field_range = field_range_for(field, field_tf, a.field_range, "--field-range", a.allow_out_of_range, a.field_tf);

  // A map of zeros would read as a perfect match (optimize refuses such a pair the same way).
  bool both = false;
  for (size_t i = 0; i < ref.values.size() && !both; ++i) both = !no_data(ref.values[i]) && !no_data(field.values[i]);
  if (!both) throw std::runtime_error("no voxel has data in both " + ref.name + " and " + field.name);
  Volume residual = residual_map(*ctx, ref, ref_tf, ref_range, field, field_tf, field_range);
  // .vti opens in ParaView with its grid and spacing; anything else is float32 raw.
  const bool vti = has_extension(a.out, ".vti");
  if (vti) write_vti(a.out, residual, "residual");
  else write_raw_float32(a.out, residual);
  const FieldRange shown = display ? *display : residual_display_range({&residual});
  if (!a.image.empty()) {
    Progress progress("rendering the residual", a.settings.height);
    RenderedImage img = render_volume(*ctx, residual, residual_transfer_function(), shown, a.settings, &progress);
    progress.finish();
    Image picture = composite_over(img, a.settings.background);
    draw_box_outline(picture, VolumeGeometry::from(residual.dims, residual.spacing, a.settings.z_scale), a.settings,
                     &ref.axes);
    if (a.color_bar) add_picture_color_bar(picture, residual_transfer_function(), shown, kResidualValueLabel, a.settings);
    write_png(a.image, picture);
  }
  outputs.commit();
  if (!globals().quiet) {
    const FiniteStats stats = finite_stats(residual.values);
    double sum = 0;
    for (float v : residual.values)
      if (std::isfinite(v)) sum += v;
    const auto& d = residual.dims;
    // The true maximum (0 when the fields match), not the display range, which never collapses.
    std::cout << "residual map " << d[0] << "x" << d[1] << "x" << d[2] << ": mean "
              << (stats.finite ? sum / double(stats.finite) : 0.0) << ", max " << (stats.finite ? stats.hi : 0.0)
              << " (0 where either field has no data)\n"
              << "  wrote " << a.out << (vti ? " (VTK ImageData)" : " (float32 little-endian)");
    // The raw reader takes the grid from names like residual_64x64x32_float32.raw.
    static const std::regex sized(R"(\d+x\d+x\d+)");
    if (!vti && !std::regex_search(std::filesystem::path(a.out).filename().string(), sized))
      std::cout << "; read it back with --dims " << d[0] << "," << d[1] << "," << d[2] << " --type float32";
    std::cout << "\n";
    if (!a.image.empty())
      std::cout << "  wrote " << a.image << " (residual TF over [" << shown.lo << ", " << shown.hi << "])\n";
  }
  return 0;
}

CommandRegistration reg(21, [](CLI::App& app) {
  auto args = std::make_shared<ResidualArgs>();
  auto* sub = app.add_subcommand("residual", "Residual map between REF with REF-TF and FIELD with FIELD-TF");
  sub->add_option("--ref", args->ref, "Reference field: FILE or FILE:VAR[,time=N][,member=N]")->required();
  sub->add_option("--ref-tf", args->ref_tf, "Reference transfer function (tfmatch JSON, XML or ParaView preset, or a built-in map name as "
                  "optimize --ref-tf)")->required();
  sub->add_option("--field", args->field, "Second field")->required();
  sub->add_option("--field-tf", args->field_tf, "Transfer function of the second field (e.g. the optimized one; any TF format)")
      ->required();
  sub->add_option("--out", args->out, "Residual map: .vti (ParaView) or .raw (float32)")->required()
      ->check(output_format(field_format()));
  sub->add_option("--image", args->image, "Also render the residual map into this PNG")->check(output_format(png_format()));
  sub->add_option("--ref-range", args->ref_range, "Reference range lo,hi (default: TF file's, else finite min/max)");
  sub->add_option("--field-range", args->field_range, "Field range lo,hi (default: TF file's, else finite min/max)");
  add_allow_out_of_range_flag(sub, args->allow_out_of_range);
  sub->add_option("--display-range", args->display_range, "Residual range lo,hi the image maps (default: 0,max)");
  add_volume_flags(sub, args->volume_flags);
  add_render_options(sub, args->settings);
  add_color_bar_flag(sub, args->color_bar);
  sub->callback([args, sub] {
    args->chosen = render_choices(*sub);
    args->image_flags = given_picture_flags(*sub, {"--display-range"});
    exit_code() = run(*args);
  });
});

}  // namespace
}  // namespace tfm::cli
