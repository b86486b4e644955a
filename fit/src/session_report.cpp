// The HTML report of `phos fit session`: the material with its units and
// uncertainties, data against fit for every stage, as inline SVG plots.

#include <cmath>

#include "phos/fit/session_fit.h"
#include "phos/util/format.h"
#include "phos/util/svg_plot.h"

namespace phos {
namespace {

std::string Escape(const std::string& text) {
  std::string out;
  for (char ch : text) {
    if (ch == '<')
      out += "&lt;";
    else if (ch == '>')
      out += "&gt;";
    else if (ch == '&')
      out += "&amp;";
    else
      out += ch;
  }
  return out;
}

// The material's value with its 1-sigma uncertainty, when there is one.
std::string WithStderr(double value, const std::optional<double>& stderr_value) {
  return FormatShort(value) + (stderr_value ? " &plusmn; " + FormatShort(*stderr_value) : std::string());
}

// The page's head, title, fit time, source and the fit's notes.
std::string ReportHeader(const SessionFit& fit, const std::string& title) {
  std::string html;
  html.append("<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>")
      .append(Escape(title))
      .append(
          "</title>\n<style>body{font-family:sans-serif;max-width:900px;margin:2em auto;color:#222}"
          "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
          "th{background:#f4f4f4}.note{color:#a33}</style></head><body>\n");
  html.append("<h1>").append(Escape(title)).append("</h1>\n");
  html.append("<p>Fitted in ")
      .append(FormatShort(fit.seconds))
      .append(" s. ")
      .append(Escape(fit.material.source))
      .append("</p>\n");
  for (const std::string& note : fit.notes) html.append("<p class=\"note\">").append(Escape(note)).append("</p>\n");
  return html;
}

// The material, with units and 1-sigma uncertainties.
std::string MaterialSection(const Material& m) {
  std::string html;
  html.append("<h2>Material</h2>\n<table><tr><th>state</th><th>kr (1/s) &plusmn; 1&sigma;</th></tr>\n");
  for (std::size_t i = 0; i < m.states.size(); ++i)
    html.append("<tr><td>")
        .append(std::to_string(i + 1))
        .append("</td><td>")
        .append(WithStderr(m.states[i].kr, m.states[i].kr_stderr))
        .append("</td></tr>\n");
  html.append(
      "</table>\n<p>ke: 1/s per unit band-integrated irradiance (the lab's irradiance unit); &Lambda;: "
      "emitted radiance per unit kr&middot;r (the camera's radiance unit). 1&sigma; uncertainties; "
      "\"not measured\": no light reached the band, so ke stays unknown.</p>\n<table><tr><th>band (nm)</th>");
  for (std::size_t i = 0; i < m.states.size(); ++i)
    html.append("<th>ke, state ").append(std::to_string(i + 1)).append("</th>");
  for (std::size_t i = 0; i < m.states.size(); ++i)
    html.append("<th>&Lambda;, state ").append(std::to_string(i + 1)).append("</th>");
  html.append("</tr>\n");
  for (int b = 0; b < m.band_count(); ++b) {
    html.append("<tr><td>").append(m.bands.BandName(b)).append("</td>");
    for (const ExcitedState& state : m.states) {
      const auto& ke = state.ke[b];
      // A reference, not a copy: GCC 12 took the copy of a std::nullopt for
      // one whose value might be read uninitialized (-Wmaybe-uninitialized).
      static const std::optional<double> kNotKnown;
      const std::optional<double>& ke_stderr =
          b < static_cast<int>(state.ke_stderr.size()) ? state.ke_stderr[b] : kNotKnown;
      html.append("<td>").append(ke ? WithStderr(*ke, ke_stderr) : "not measured").append("</td>");
    }
    for (const ExcitedState& state : m.states) html.append("<td>").append(FormatShort(state.Lambda[b])).append("</td>");
    html.append("</tr>\n");
  }
  html.append("</table>\n");
  return html;
}

// The fitted material against the known one (simulated captures).
std::string ComparisonSection(const Material& m, const MaterialComparison& c) {
  std::string html;
  html.append("<h2>Against the known material</h2>\n<p>kr off by ");
  for (std::size_t i = 0; i < c.kr_relative_error.size(); ++i)
    html.append(i ? ", " : "").append(FormatShort(100 * c.kr_relative_error[i])).append("%");
  html.append("; normalized emission spectrum L1 ")
      .append(FormatShort(c.spectrum_l1))
      .append(".</p>\n<table><tr><th>state</th>");
  for (int b = 0; b < m.band_count(); ++b) html.append("<th>ke error, ").append(m.bands.BandName(b)).append("</th>");
  html.append("</tr>\n");
  for (std::size_t i = 0; i < c.ke_relative_error_per_state.size(); ++i) {
    html.append("<tr><td>").append(std::to_string(i + 1)).append("</td>");
    for (const auto& e : c.ke_relative_error_per_state[i])
      html.append("<td>").append(e ? FormatShort(100 * *e) + "%" : "-").append("</td>");
    html.append("</tr>\n");
  }
  html.append("</table>\n");
  return html;
}

// Decay: data against fit, and residuals.
std::string DecaySection(const SessionFit& fit) {
  const DecayFitSummary& d = *fit.decay;
  std::string html;
  html.append("<h2>Decay</h2>\n<p>nc = ")
      .append(std::to_string(d.n_components))
      .append(": ")
      .append(Escape(d.choice))
      .append(". BIC per nc: ");
  for (std::size_t i = 0; i < d.bic.size(); ++i)
    html.append(i ? ", " : "")
        .append(std::to_string(i + 1))
        .append(": ")
        .append(std::isfinite(d.bic[i]) ? FormatShort(d.bic[i]) : "invalid");
  html.append(". rss ").append(FormatShort(d.rss)).append(" (DN/s)&sup2;.</p>\n");
  std::vector<PlotSeries> data_fit, residuals;
  for (int c = 0; c < fit.decay_curve.channel_count(); ++c) {
    PlotSeries data(fit.decay_curve.names[c] + " measured"), model(fit.decay_curve.names[c] + " fit"),
        residual(fit.decay_curve.names[c]);
    data.markers = true;
    data.line = false;
    data.color = model.color = residual.color = ChannelOrPaletteColor(fit.decay_curve.names[c], c);
    model.dashed = true;
    residual.markers = true;
    for (std::size_t j = 0; j < fit.decay_curve.size(); ++j) {
      const double t = fit.decay_curve.t_s[j], y = fit.decay_curve.channels[c][j], f = EvaluateDecay(d, c, t);
      data.x.push_back(t);
      data.y.push_back(y);
      model.x.push_back(t);
      model.y.push_back(f);
      residual.x.push_back(t);
      residual.y.push_back(y - f);
    }
    data_fit.push_back(data);
    data_fit.push_back(model);
    residuals.push_back(residual);
  }
  PlotOptions o;
  o.title = "Decay after saturation: data and fit";
  o.x_label = "time after light-off (s)";
  o.y_label = "signal / exposure (DN/s)";
  o.log_y = true;
  html.append(PlotSvg(data_fit, o)).append("\n");
  o.title = "Decay residuals";
  o.log_y = false;
  o.y_label = "data - fit (DN/s)";
  o.height_px = 280;
  html.append(PlotSvg(residuals, o)).append("\n");
  return html;
}

// Excitation per state and light.
std::string ExcitationSection(const SessionFit& fit) {
  const StateExcitationFit& e = *fit.state_excitation;
  std::vector<double> kr;
  for (const ExcitedState& state : fit.material.states) kr.push_back(state.kr);
  std::string html;
  html.append(
          "<h2>Excitation</h2>\n<p>Each charge's first frame and its decay tail, split into the states by "
          "their kr; ")
      .append(std::to_string(e.frames))
      .append(" frames, ")
      .append(std::to_string(e.iterations))
      .append(" Ceres iterations, ")
      .append(e.converged ? "converged" : "<b>not converged</b>: " + Escape(e.termination))
      .append("; condition number of the weighted Jacobian (relative parameters) ")
      .append(FormatShort(e.condition_number))
      .append(".</p>\n<table><tr><th>light</th>");
  for (std::size_t i = 0; i < kr.size(); ++i)
    html.append("<th>a, state ").append(std::to_string(i + 1)).append(" (1/s) &plusmn; 1&sigma;</th>");
  html.append("<th>charges</th></tr>\n");
  std::vector<PlotSeries> series;
  int index = 0;
  for (const auto& light : fit.excitation) {
    html.append("<tr><td>").append(Escape(light.light)).append("</td>");
    const auto a = e.a.find(light.light);
    const auto a_stderr = e.a_stderr.find(light.light);
    for (std::size_t i = 0; i < kr.size(); ++i)
      html.append("<td>")
          .append(a == e.a.end() ? "-" : FormatShort(a->second[i]) + " &plusmn; " + FormatShort(a_stderr->second[i]))
          .append("</td>");
    html.append("<td>").append(std::to_string(light.samples.size())).append("</td></tr>\n");
    if (a == e.a.end()) continue;
    PlotSeries data(light.light + " measured"), model(light.light + " fit");
    data.markers = true;
    data.line = false;
    data.color = model.color = PaletteColor(index++);
    model.dashed = true;
    for (const ExcitationSample& s : light.samples) {
      data.x.push_back(s.charge_s);
      data.y.push_back(s.value);
      model.x.push_back(s.charge_s);
      model.y.push_back(ExcitationFrameSignal(e.S, a->second, kr, s.charge_s, {s.delay_s, s.exposure_s, 0.0}));
    }
    series.push_back(data);
    series.push_back(model);
  }
  html.append("</table>\n");
  PlotOptions o;
  o.title = "Excitation: first frame after charging for t, and the fit";
  o.x_label = "charge time t (s)";
  o.y_label = "signal / exposure (DN/s)";
  o.log_x = true;
  html.append(PlotSvg(series, o)).append("\n");
  return html;
}

// The joint refinement beside the sequential fit.
std::string JointSection(const SessionFit& fit) {
  const JointFit& j = *fit.joint;
  std::string html;
  html.append(
          "<h2>Joint refinement</h2>\n<p>Every kr, the decay amplitudes and backgrounds, every state's a "
          "under every light and S fitted at once to the decay and all excitation frames (one "
          "photon-counting chi-square), beside the sequential fit of the paper (kr from the decay alone, "
          "then the excitation). ")
      .append(std::to_string(j.iterations))
      .append(" Ceres iterations")
      .append(j.converged ? "." : ", <b>not converged</b>: " + Escape(j.termination))
      .append("</p>\n<table><tr><th></th><th>sequential</th><th>joint</th></tr>\n");
  for (std::size_t i = 0; i < j.kr.size() && fit.decay && i < fit.decay->components.size(); ++i)
    html.append("<tr><td>kr, state ")
        .append(std::to_string(i + 1))
        .append(" (1/s)</td><td>")
        .append(FormatShort(fit.decay->components[i].rate))
        .append("</td><td>")
        .append(FormatShort(j.kr[i]))
        .append(" &plusmn; ")
        .append(FormatShort(j.kr_stderr[i]))
        .append("</td></tr>\n");
  if (fit.state_excitation)
    for (const auto& [light, values] : j.a) {
      const auto sequential = fit.state_excitation->a.find(light);
      for (std::size_t i = 0; i < values.size(); ++i)
        html.append("<tr><td>a under ")
            .append(Escape(light))
            .append(", state ")
            .append(std::to_string(i + 1))
            .append(" (1/s)</td><td>")
            .append(sequential == fit.state_excitation->a.end() ? "-" : FormatShort(sequential->second[i]))
            .append("</td><td>")
            .append(FormatShort(values[i]))
            .append("</td></tr>\n");
    }
  html.append("<tr><td>weighted SS, decay</td><td>")
      .append(FormatShort(j.decay_sequential))
      .append("</td><td>")
      .append(FormatShort(j.decay_joint))
      .append("</td></tr>\n<tr><td>weighted SS, excitation</td><td>")
      .append(FormatShort(j.excitation_sequential))
      .append("</td><td>")
      .append(FormatShort(j.excitation_joint))
      .append("</td></tr>\n<tr><th>weighted SS, total</th><th>")
      .append(FormatShort(j.decay_sequential + j.excitation_sequential))
      .append("</th><th>")
      .append(FormatShort(j.decay_joint + j.excitation_joint))
      .append("</th></tr>\n</table>\n<p>")
      .append(j.decay_joint + j.excitation_joint < j.decay_sequential + j.excitation_sequential
                  ? "The joint fit fits the data better (lower total)."
                  : "The sequential fit is already at the joint optimum.")
      .append("</p>\n");
  return html;
}

// LVF calibration: the known lines against their centroid column.
std::string CalibrationSection(const LvfCalibrationFit& c) {
  std::string html;
  html.append("<h2>LVF calibration</h2>\n<p>centre(x) = ")
      .append(FormatShort(c.center0_nm))
      .append(" nm + ")
      .append(FormatShort(c.nm_per_column))
      .append(" nm &times; column; pass band ")
      .append(FormatShort(c.fwhm_nm))
      .append(" nm FWHM; line residual rms ")
      .append(FormatShort(c.rms_residual_nm))
      .append(" nm.</p>\n");
  PlotSeries lines("lines"), model("fitted line");
  lines.markers = true;
  lines.line = false;
  for (const auto& line : c.lines) {
    lines.x.push_back(line.column);
    lines.y.push_back(line.wavelength_nm);
  }
  model.x = {0.0, static_cast<double>(c.width - 1)};
  model.y = {c.CenterNm(0), c.CenterNm(c.width - 1)};
  PlotOptions o;
  o.title = "LVF: known lines against their centroid column";
  o.x_label = "column";
  o.y_label = "wavelength (nm)";
  o.height_px = 320;
  html.append(PlotSvg({lines, model}, o)).append("\n");
  return html;
}

// The emission spectrum: the first frame through the filter, and per band.
std::string SpectrumSection(const SessionFit& fit) {
  const Material& m = fit.material;
  const auto& frame = fit.spectrum->frames.front();
  PlotSeries measured("measured (first frame)"), modelled("reconstruction through the filter");
  measured.markers = true;
  measured.line = false;
  for (std::size_t x = 0; x < frame.measured.size(); ++x) {
    const double nm = fit.calibration->CenterNm(static_cast<double>(x));
    measured.x.push_back(nm);
    measured.y.push_back(frame.measured[x]);
    modelled.x.push_back(nm);
    modelled.y.push_back(frame.modelled[x]);
  }
  PlotOptions o;
  o.title = "Emission spectrum through the LVF";
  o.x_label = "wavelength (nm)";
  o.y_label = "column signal (DN/s)";
  std::string html;
  html.append("<h2>Emission spectrum</h2>\n").append(PlotSvg({measured, modelled}, o)).append("\n");
  PlotSeries shape("normalized band radiance");
  shape.markers = true;
  for (int b = 0; b < m.band_count(); ++b) {
    shape.x.push_back(m.bands.center_nm(b));
    shape.y.push_back(fit.spectrum->shape[b]);
  }
  o.title = "Emission spectrum per band (normalized)";
  o.y_label = "share of the emission";
  o.height_px = 320;
  html.append(PlotSvg({shape}, o)).append("\n");
  return html;
}

}  // namespace

std::string SessionReportHtml(const SessionFit& fit, const std::string& title,
                              const std::optional<MaterialComparison>& comparison) {
  std::string html = ReportHeader(fit, title) + MaterialSection(fit.material);
  if (comparison) html += ComparisonSection(fit.material, *comparison);
  if (fit.decay) html += DecaySection(fit);
  if (!fit.excitation.empty() && fit.state_excitation) html += ExcitationSection(fit);
  if (fit.joint) html += JointSection(fit);
  if (fit.calibration) html += CalibrationSection(*fit.calibration);
  if (fit.spectrum && !fit.spectrum->frames.empty()) html += SpectrumSection(fit);
  html.append("</body></html>\n");
  return html;
}

}  // namespace phos
