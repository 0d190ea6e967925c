// `tfmatch render`: direct volume rendering of one field with one TF into a PNG.
#include <chrono>
#include <iostream>

#include "cli.h"
#include "input_options.h"
#include "output_options.h"
#include "render_options.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/kernels/render.h"
#include "tfmatch/model/builtin_tf.h"
#include "tfmatch/model/progress.h"
#include "tfmatch/model/transfer_function.h"
#include "tfmatch/report/png_io.h"
#include "tfmatch/report/tf_plot.h"

namespace tfm::cli {
namespace {

struct RenderArgs {
  std::string volume, tf, out, range;
  bool allow_out_of_range = false;
  bool color_bar = false;
  std::vector<std::string> markers;
  VolumeFlags volume_flags;
  RenderSettings settings;
  RenderChoices chosen;
};

int run(RenderArgs a) {
  set_progress_enabled(!globals().quiet);
  FilePlan().input_spec(a.volume, "--volume").input_spec(a.tf, "--tf").output(a.out, "--out").check();
  if (!a.range.empty()) parse_range(a.range, "--range");  // a bad range fails before anything loads
  validate(a.settings);
  auto ctx = make_context();
  check_render_size(*ctx, a.settings);  // before loading: a too-large image fails in a second
  OutputBatch outputs;
  Volume volume = load_volume(a.volume, a.volume_flags.options({a.volume}));
  if (const std::string note = apply_grid_defaults(a.settings, volume.dims, volume.spacing, a.chosen); !note.empty())
    print_note(note);
  std::vector<std::string> notes;
  TransferFunction tf = read_transfer_function(a.tf, {}, &notes);
  for (const std::string& n : notes) print_note(n);
  const FieldRange range = field_range_for(volume, tf, a.range, "--range", a.allow_out_of_range, a.tf);
  const std::vector<GridIndex> markers = resolve_markers(volume, a.markers);

  const auto t0 = std::chrono::steady_clock::now();
  RenderedImage image;
  {
    Progress progress("rendering", a.settings.height);
    image = render_volume(*ctx, volume, tf, range, a.settings, &progress);
  }
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  Image picture = composite_over(image, a.settings.background);
  const VolumeGeometry geometry = VolumeGeometry::from(volume.dims, volume.spacing, a.settings.z_scale);
  draw_box_outline(picture, geometry, a.settings, &volume.axes, markers);
  draw_markers(picture, geometry, a.settings, markers);
  if (a.color_bar) add_picture_color_bar(picture, tf, range, field_label(volume), a.settings);
  write_png(a.out, picture);
  outputs.commit();
  // No ray met the box (a grid of one voxel in two axes is a line thinner than a pixel at a
  // small size): a picture of the background only is not the volume, so say so.
  // A step longer than the box's thinnest side can carry every ray across it without a sample.
  const double finest = std::min({geometry.axis_scale.x, geometry.axis_scale.y, geometry.axis_scale.z});
  const glm::dvec3 extent = 2.0 * geometry.half_extent();
  const double thinnest = std::min({extent.x, extent.y, extent.z}) / finest;
  if (image.samples() == 0 && a.settings.step_voxels >= thinnest)
    std::cerr << "tfmatch: warning: no sample was taken, so the picture shows only the background: the step (--step "
              << a.settings.step_voxels << " voxels) is as long as the volume's box is thin (" << thinnest
              << " voxels), so rays can cross it between two samples; a smaller --step shows it (or, if no ray met "
                 "the box, a larger --width/--height or another --azimuth/--elevation)\n";
  else if (image.samples() == 0)
    std::cerr << "tfmatch: warning: no ray of the " << a.settings.width << "x" << a.settings.height
              << " picture met the volume's box (" << volume.dims[0] << "x" << volume.dims[1] << "x" << volume.dims[2]
              << " voxels), so it shows only the background; a larger --width/--height, a smaller --distance or "
                 "another --azimuth/--elevation shows it\n";
  if (!globals().quiet)
    std::cout << "rendered " << volume.name << " (" << volume.dims[0] << "x" << volume.dims[1] << "x"
              << volume.dims[2] << ", range [" << range.lo << ", " << range.hi << "]) at " << a.settings.width
              << "x" << a.settings.height << " on " << ctx->device_name() << ": " << image.samples()
              << " samples in " << ms << " ms (upload included)\n  wrote " << a.out << "\n";
  return 0;
}

CommandRegistration reg(20, [](CLI::App& app) {
  auto args = std::make_shared<RenderArgs>();
  auto* sub = app.add_subcommand("render", "Render a volume with a transfer function into a PNG image");
  sub->add_option("--volume", args->volume, "Volume file, or FILE:VAR[,time=N][,member=N]")->required();
  sub->add_option("--tf", args->tf, "Transfer function (tfmatch JSON, framework XML or ParaView preset[:NAME]), or a built-in map: " +
                  builtin_tf_syntax() + " (a file of that name wins)")->required();
  sub->add_option("--out", args->out, "Output image (PNG)")->required()->check(output_format(png_format()));
  sub->add_option("--range", args->range, "Field range lo,hi mapped to the TF (default: TF file's, else finite min/max)");
  add_allow_out_of_range_flag(sub, args->allow_out_of_range);
  add_volume_flags(sub, args->volume_flags);
  add_render_options(sub, args->settings);
  add_color_bar_flag(sub, args->color_bar);
  add_marker_option(sub, args->markers);
  sub->callback([args, sub] {
    args->chosen = render_choices(*sub);
    exit_code() = run(*args);
  });
});

}  // namespace
}  // namespace tfm::cli
