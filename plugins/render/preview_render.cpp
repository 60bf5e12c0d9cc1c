#include "tbsp/plugins/preview_render.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cstdio>
#include <numeric>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tbsp/core/error.h"
#include "tbsp/io/atomic_file.h"

namespace tbsp {

Eigen::MatrixX3d colormap(const Eigen::VectorXd& values, double lo, double hi) {
  Eigen::MatrixX3d C(values.rows(), 3);
  for (Eigen::Index i = 0; i < values.rows(); ++i) {
    double t = hi > lo ? std::clamp((values(i) - lo) / (hi - lo), 0.0, 1.0) : 0.0;
    // piecewise: blue(0) -> cyan(.25) -> green(.5) -> yellow(.75) -> red(1)
    const double r = std::clamp(2.0 * t - 0.5, 0.0, 1.0);
    const double g = t < 0.75 ? std::clamp(4.0 * t, 0.0, 1.0) : std::clamp(4.0 * (1.0 - t), 0.0, 1.0);
    const double b = std::clamp(1.0 - 2.0 * t, 0.0, 1.0);
    C.row(i) << r, g, b;
  }
  return C;
}

void render_panels_png(const std::string& path, const std::vector<RenderPanel>& panels, const RenderOptions& o) {
  if (panels.empty()) throw InvalidInput("[tbsp::render_panels_png] nothing to render");
  const double az = o.azimuth_deg * M_PI / 180, el = o.elevation_deg * M_PI / 180;
  // camera: rotate world so the view direction is -z
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(el, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(-az, Eigen::Vector3d::UnitY()))
                                .toRotationMatrix();
  const Eigen::Vector3d light = Eigen::Vector3d(0.3, 0.5, 1.0).normalized();
  const bool any_bar = std::any_of(panels.begin(), panels.end(), [](const RenderPanel& p) { return p.colorbar; });
  const int title_h = 24, bar_h = any_bar ? 54 : 0;            // title strip on top, colour bar below
  const int draw_h = o.panel_height - title_h - bar_h;          // the drawing area
  cv::Mat canvas(o.panel_height, o.panel_width * int(panels.size()), CV_8UC3, cv::Scalar(255, 255, 255));
  Eigen::Vector2d gmin(1e300, 1e300), gmax(-1e300, -1e300);
  std::vector<Eigen::MatrixX3d> P(panels.size());
  std::vector<Eigen::MatrixX3d> Q(panels.size());
  for (std::size_t k = 0; k < panels.size(); ++k) {
    P[k] = (panels[k].mesh.V * R.transpose());
    Q[k] = panels[k].points * R.transpose();
    if (Q[k].rows()) {
      gmin = gmin.cwiseMin(Q[k].leftCols<2>().colwise().minCoeff().transpose());
      gmax = gmax.cwiseMax(Q[k].leftCols<2>().colwise().maxCoeff().transpose());
    }
    if (P[k].rows() == 0) continue;
    gmin = gmin.cwiseMin(P[k].leftCols<2>().colwise().minCoeff().transpose());
    gmax = gmax.cwiseMax(P[k].leftCols<2>().colwise().maxCoeff().transpose());
  }
  for (std::size_t k = 0; k < panels.size(); ++k) {
    const auto& m = panels[k].mesh;
    const auto& X = P[k];
    Eigen::Vector2d lo = gmin, hi = gmax;
    if (!o.shared_frame && (X.rows() || Q[k].rows())) {
      lo = Eigen::Vector2d::Constant(1e300);
      hi = Eigen::Vector2d::Constant(-1e300);
      for (const Eigen::MatrixX3d* Y : {static_cast<const Eigen::MatrixX3d*>(&X), static_cast<const Eigen::MatrixX3d*>(&Q[k])})
        if (Y->rows()) {
          lo = lo.cwiseMin(Y->leftCols<2>().colwise().minCoeff().transpose());
          hi = hi.cwiseMax(Y->leftCols<2>().colwise().maxCoeff().transpose());
        }
    }
    const double margin = 0.08;
    const double s = (1 - 2 * margin) * std::min(o.panel_width / std::max(hi.x() - lo.x(), 1e-300),
                                                 draw_h / std::max(hi.y() - lo.y(), 1e-300));
    const Eigen::Vector2d c = 0.5 * (lo + hi);
    const int ox = int(k) * o.panel_width;
    auto px = [&](const Eigen::RowVector3d& p) {
      const double x = ox + o.panel_width / 2.0 + s * (p.x() - c.x());
      const double y = title_h + draw_h / 2.0 - s * (p.y() - c.y());
      return cv::Point(int(std::lround(x * 16)), int(std::lround(y * 16)));
    };
    std::vector<int> order(static_cast<std::size_t>(m.F.rows()));
    std::iota(order.begin(), order.end(), 0);
    std::vector<double> depth(order.size());
    for (std::size_t f = 0; f < order.size(); ++f)
      depth[f] = X(m.F(Eigen::Index(f), 0), 2) + X(m.F(Eigen::Index(f), 1), 2) + X(m.F(Eigen::Index(f), 2), 2);
    std::sort(order.begin(), order.end(), [&](int a, int b) { return depth[std::size_t(a)] < depth[std::size_t(b)]; });
    const bool colored = m.C.rows() == m.V.rows() && m.V.rows() > 0;
    for (int f : order) {
      const Eigen::RowVector3d a = X.row(m.F(f, 0)), b = X.row(m.F(f, 1)), cc = X.row(m.F(f, 2));
      // edges in pixels: a mesh in tiny (1e-100) or huge units keeps a finite, non-zero normal
      Eigen::Vector3d n = ((b - a) * s).cross((cc - a) * s).transpose();
      if (n.norm() <= 0) continue;
      n.normalize();
      const double shade = 0.25 + 0.75 * std::abs(n.dot(light));
      Eigen::Vector3d base(0.75, 0.78, 0.85);
      if (colored) base = ((m.C.row(m.F(f, 0)) + m.C.row(m.F(f, 1)) + m.C.row(m.F(f, 2))) / 3.0).transpose();
      if (n.z() < 0 && !colored) base = Eigen::Vector3d(0.85, 0.6, 0.55);  // back faces tinted
      const cv::Point pts[3] = {px(a), px(b), px(cc)};
      const cv::Scalar col(255 * shade * base.z(), 255 * shade * base.y(), 255 * shade * base.x());
      cv::fillConvexPoly(canvas, pts, 3, col, cv::LINE_AA, 4);
    }
    if (Q[k].rows()) {
      std::vector<int> po(static_cast<std::size_t>(Q[k].rows()));
      std::iota(po.begin(), po.end(), 0);
      std::sort(po.begin(), po.end(), [&](int a, int b) { return Q[k](a, 2) < Q[k](b, 2); });
      const double zlo = Q[k].col(2).minCoeff(), zhi = Q[k].col(2).maxCoeff();
      const bool pc = panels[k].point_colors.rows() == Q[k].rows();
      for (int i : po) {
        const double shade = 0.35 + 0.65 * (zhi > zlo ? (Q[k](i, 2) - zlo) / (zhi - zlo) : 1.0);
        Eigen::Vector3d base = pc ? Eigen::Vector3d(panels[k].point_colors.row(i).transpose()) : Eigen::Vector3d(0.2, 0.35, 0.8);
        cv::circle(canvas, px(Q[k].row(i)), 16, cv::Scalar(255 * shade * base.z(), 255 * shade * base.y(), 255 * shade * base.x()),
                   cv::FILLED, cv::LINE_AA, 4);
      }
    }
    cv::putText(canvas, panels[k].title, cv::Point(ox + 8, 17), cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    if (panels[k].colorbar) {
      // horizontal bar: colormap() from lo (left) to hi (right), with both values and the label
      const int x0 = ox + 40, x1 = ox + o.panel_width - 40, y0 = o.panel_height - bar_h + 6, y1 = y0 + 12;
      for (int x = x0; x <= x1; ++x) {
        const Eigen::MatrixX3d col = colormap(Eigen::VectorXd::Constant(1, double(x - x0) / double(x1 - x0)), 0, 1);
        cv::line(canvas, cv::Point(x, y0), cv::Point(x, y1), cv::Scalar(255 * col(0, 2), 255 * col(0, 1), 255 * col(0, 0)));
      }
      cv::rectangle(canvas, cv::Point(x0, y0), cv::Point(x1, y1), cv::Scalar(90, 90, 90));
      auto num = [](double v) {
        char b[32];
        std::snprintf(b, sizeof b, "%.3g", v);
        return std::string(b);
      };
      const auto font = cv::FONT_HERSHEY_SIMPLEX;
      cv::putText(canvas, num(panels[k].colorbar_lo), cv::Point(x0 - 4, y1 + 14), font, 0.38, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
      const std::string hi_s = num(panels[k].colorbar_hi);
      int base = 0;
      const cv::Size hs = cv::getTextSize(hi_s, font, 0.38, 1, &base);
      cv::putText(canvas, hi_s, cv::Point(x1 - hs.width + 4, y1 + 14), font, 0.38, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
      const cv::Size ls = cv::getTextSize(panels[k].colorbar_label, font, 0.38, 1, &base);
      cv::putText(canvas, panels[k].colorbar_label, cv::Point(ox + (o.panel_width - ls.width) / 2, y1 + 28), font, 0.38,
                  cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    }
    if (k > 0) cv::line(canvas, cv::Point(ox, 0), cv::Point(ox, o.panel_height), cv::Scalar(180, 180, 180));
  }
  std::vector<uchar> png;
  if (!cv::imencode(".png", canvas, png)) throw FileError("cannot encode PNG for '" + path + "'");
  AtomicFile f(path, true);
  f.stream().write(reinterpret_cast<const char*>(png.data()), std::streamsize(png.size()));
  f.commit();
}

}  // namespace tbsp
